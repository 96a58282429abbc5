"""The stage-scales bench (``bench/linescan/stage_scales.py``), on which the give-up's threshold
rests: it records every stage of a real refinement and puts the names it wraps back after, and
it tells sound refinements from poor ones and counts those a give-up would drop."""

from __future__ import annotations

import numpy as np
from bench.linescan.reuse_diag import at_truth
from bench.linescan.stage_scales import Job, Refinement, recording, stage_rows, step_rows

from tumblescan import Scanner, Scene
from tumblescan.linescan.dense import attempts, degeneracy, refine

from ..conftest import motion_for


def test_every_stage_of_a_refinement_is_recorded_and_the_names_put_back() -> None:
    scene = Scene(scanner=Scanner(lines=160, pixels=160))
    _, data, mapping, _ = at_truth(motion_for(1, distance_m=50.0), scene, 1)
    names = (refine._iterate, refine.weights, attempts.refine_dense, degeneracy.refine_dense)
    with recording() as made:
        fit = attempts.refine_dense(data, mapping.x, noise=scene.scanner.noise)
        attempts.refine_dense(data, fit.x, noise=scene.scanner.noise, converged=True)
        # A threshold under every right motion's scale: given up after the first stage.
        attempts.refine_dense(data, mapping.x, noise=scene.scanner.noise, give_up_scale=0.1)
    assert (refine._iterate, refine.weights, attempts.refine_dense, degeneracy.refine_dense) == names
    assert [len(r.stages) for r in made] == [3, 1, 1] and [r.full for r in made] == [True, False, True]
    # Each stage's steps, the last of them the scale the stage ended at.
    assert [len(r.steps) for r in made] == [3, 1, 1]
    assert all(steps and steps[-1] == scale for r in made for steps, scale in zip(r.steps, r.stages, strict=True))
    assert [r.given_up for r in made] == [0, 0, 1]
    # From the truth every stage stands near 1.
    assert all(0.3 < s < 1.5 for r in made for s in r.stages)


def test_sound_and_poor_refinements_are_told_apart_per_stage() -> None:
    sound = Refinement([1.0, 0.5, 0.9], 0.98, 0, False, True)
    wrong = Refinement([0.0, 32.1], 32.1, 2, False, True)
    lost = Refinement([31.9, 36.0, 36.7], 36.8, 0, True, True)
    check = Refinement([1.1], 1.1, 0, False, False)  # the validation's: not from a start
    rows = stage_rows([Job("long-array:100:1", 4, 20.0, True, [wrong, lost, sound, check])])
    # After stage 1: one sound (1.0), two poor (0.0 and 31.9), one of them over the give-up.
    assert rows[0][1] == 1 and rows[0][3] == 2 and rows[0][4] == "0.0 31.9" and rows[0][5:] == [0, 1]
    assert rows[1][1] == 1 and rows[1][4] == "32.1 36.0" and rows[1][5:] == [0, 2]
    assert np.isclose(float(str(rows[1][2]).split(" / ")[0]), 0.5)


def test_the_first_stage_is_read_step_by_step() -> None:
    """Sound refinements' largest scale and the others' smallest after k steps of the first
    stage, among those still stepping, and how many of each stand over the give-up's 9."""
    sound = Refinement([1.0], 0.98, 0, False, True, [[300.0, 30.0, 5.0, 1.2, 1.0]])
    slow = Refinement([1.0], 1.0, 0, False, True, [[100.0, 50.0, 20.0, 12.0, 4.0, 2.0]])
    wrong = Refinement([40.0], 40.0, 1, False, True, [[120.0, 45.0, 43.0, 41.0, 40.0, 40.0]])
    check = Refinement([1.1], 1.1, 0, False, False, [[1.1]])  # the validation's: not from a start
    rows = step_rows([Job("long-array:100:1", 4, 20.0, True, [sound, slow, wrong, check])], after=(2, 3, 5))
    assert rows[0] == [2, 2, "20.00", 1, 1, "43.00", 1]
    assert rows[1] == [3, 2, "12.00", 1, 1, "41.00", 1]
    # After 5 steps the sound one had stopped: only the slow one is still stepping.
    assert rows[2] == [5, 1, "2.00", 0, 1, "40.00", 1]
