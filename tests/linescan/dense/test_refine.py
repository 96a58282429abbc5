"""The refinement's convergence on a nearly degenerate motion: spin and precession about axes 12 deg
from opposite, so the rates' split is a direction of tiny curvature. Once Levenberg-Marquardt's
damping (``lam diag H``) was on, it all but stopped the motion along that direction, and the small
steps passed for convergence 10 bounds off the optimum; convergence is now judged by the
Gauss-Newton step. On another CPU (other rounding in the BLAS) every start then crept along the
valley and ended 29 deg off: the steps are now taken in the rotation vectors, where the valley is
straight (``step_coords``, tests/linescan/dense/test_step_coords.py). And a start in another basin is
given up in the first or second stage (after it, or within it once 8 of its steps leave the
residuals over the give-up's scale) when another start remains."""

from __future__ import annotations

import numpy as np
import pytest
from bench.linescan.dense import errors
from bench.linescan.reuse_diag import at_truth
from bench.linescan.stage_scales import vote_replaced

from tumblescan import Scanner, Scene, TimedCloud, estimate_from_frames, random_motion, simulate_frames
from tumblescan.linescan.dense import attempts, refine
from tumblescan.linescan.frames import assemble_frames
from tumblescan.target.shapes import LongArrayShape


def test_a_nearly_degenerate_motion_is_refined_to_its_optimum() -> None:
    """The real-shapes bench's long array at 100 m seed 5 (its hardest case): within the issue's
    limits (0.1 deg, 0.05 deg/s) and 3 reported sigmas; before, 0.93 deg and 0.24 deg/s."""
    motion = random_motion(np.random.default_rng(5), distance_m=100.0)
    spin, precession = np.asarray(motion.spin_axis), np.asarray(motion.precession_axis)
    assert np.degrees(np.arccos(abs(float(spin @ precession)))) < 15
    scene = Scene(scanner=Scanner(lines=512, pixels=512), shape=LongArrayShape())
    sim = simulate_frames(motion, scene, seed=5)
    frames = assemble_frames(TimedCloud(sim.xyz_m, sim.t_s, {"frame": sim.frame, "line": sim.line}))
    e = errors(estimate_from_frames(frames), motion)
    assert e["spin_axis_deg"] <= 0.1 and e["precession_axis_deg"] <= 0.1, e
    assert e["spin_rate_deg_s"] <= 0.05 and e["precession_rate_deg_s"] <= 0.05, e
    for p in ("spin_axis", "spin_rate", "precession_axis", "precession_rate"):
        assert e[f"{p}_sigma"] <= 3, (p, e)


def test_a_start_in_another_basin_is_given_up_after_the_first_stage() -> None:
    """The real-shapes bench's long array at 100 m seed 1, its vote's motion replaced by another
    motion's turns (seed 3's: another basin). On an Intel Xeon the vote itself led there: its
    residuals stood 17.7 times their size after the first stage of refinement (a sound start's:
    1.0), and it was refined 9 s more to 22.8; which basin the vote finds varies with the CPU's
    rounding (an AMD EPYC's found the right one), so the wrong start is made here. It is given up
    in the first stage, and the consensus's motion is within the limits."""
    motion = random_motion(np.random.default_rng(1), distance_m=100.0)
    scene = Scene(scanner=Scanner(lines=512, pixels=512), shape=LongArrayShape())
    sim = simulate_frames(motion, scene, seed=1)
    frames = assemble_frames(TimedCloud(sim.xyz_m, sim.t_s, {"frame": sim.frame, "line": sim.line}))
    with vote_replaced(3, 100.0):
        result = estimate_from_frames(frames)
    tried = next(w for w in result.warnings if "start(s) tried before" in w)
    assert "registration+cone+dense: residuals" in tried and "in the first stage of refinement (given up" in tried
    assert "the motion comes from registration+consensus+dense" in tried
    e = errors(result, motion)
    assert e["spin_axis_deg"] <= 0.1 and e["precession_axis_deg"] <= 0.1, e
    assert e["spin_rate_deg_s"] <= 0.05 and e["precession_rate_deg_s"] <= 0.05, e
    for p in ("spin_axis", "spin_rate", "precession_axis", "precession_rate"):
        assert e[f"{p}_sigma"] <= 3, (p, e)


@pytest.mark.parametrize(
    ("scales", "give_up_scale", "stages_run", "given_up"),
    [
        ([20.0, 1.0, 1.0], 9.0, 1, 1),
        # A start that matched next to nothing in the first stage (scale 0) and shows in the second.
        ([0.0, 32.1, 7.2], 9.0, 2, 2),
        # The last stage is never given up: its fit is the refinement's.
        ([1.0, 1.0, 20.0], 9.0, 3, 0),
        ([20.0, 32.1, 36.7], None, 3, 0),
        # A converged start runs the last stage alone: never given up.
        ([20.0], 9.0, 1, 0),
    ],
)
def test_a_refinement_is_given_up_after_any_stage_but_the_last(
    monkeypatch: pytest.MonkeyPatch, scales: list[float], give_up_scale: float | None, stages_run: int, given_up: int
) -> None:
    """Each stage's residual scale replaced by ``scales``: the refinement stops after the first
    stage over ``give_up_scale`` but the last, and says after which."""
    scene = Scene(scanner=Scanner(lines=160, pixels=160))
    _, data, mapping, _ = at_truth(random_motion(np.random.default_rng(1), distance_m=50.0), scene, 1)
    iterate, ran = refine._iterate, list[float]()

    def scripted(*args: object, **kwargs: object) -> tuple[object, ...]:
        out = iterate(*args, **kwargs)  # type: ignore[arg-type]
        ran.append(scales[len(ran)])
        return (*out[:-1], ran[-1])

    monkeypatch.setattr(refine, "_iterate", scripted)
    converged = len(scales) == 1
    fit = refine.refine_dense(
        data, mapping.x, noise=scene.scanner.noise, give_up_scale=give_up_scale, converged=converged
    )
    assert len(ran) == stages_run and fit.given_up == given_up
    why = attempts.poor_fit(fit)
    if given_up:
        assert fit.given_up_scale == scales[given_up - 1]
        stage = ("first", "second")[given_up - 1]
        size = f"residuals {scales[given_up - 1]:.1f} times their expected size"
        assert why == f"{size} in the {stage} stage of refinement (given up there)"
    else:
        assert why is None  # from the truth every stage's own scale is about 1


@pytest.mark.parametrize(
    ("scales", "given_up", "steps"),
    [
        ((50.0, 50.0, 50.0), 1, 8),
        ((5.0, 50.0, 50.0), 2, 15 + 8),
        # The last stage is never given up, nor any stage standing under 9.
        ((5.0, 5.0, 50.0), 0, 15 + 15 + 6),
    ],
)
def test_a_stage_is_given_up_once_its_steps_leave_the_residuals_over_the_scale(
    monkeypatch: pytest.MonkeyPatch, scales: tuple[float, float, float], given_up: int, steps: int
) -> None:
    """Each stage's every linearisation scaled ``scales[stage]``, and every step stopped (no stage
    converges): a stage but the last stops after ``GIVE_UP_STEPS`` steps when its scale stands
    over the give-up's 9 (a wrong start's 15 steps at 22-160 cost 4-9 s), else runs all its steps."""
    scene = Scene(scanner=Scanner(lines=160, pixels=160))
    _, data, mapping, _ = at_truth(random_motion(np.random.default_rng(1), distance_m=50.0), scene, 1)
    iterate, weights, stage = refine._iterate, refine.weights, [-1]

    def counted(*args: object, **kwargs: object) -> tuple[object, ...]:
        stage[0] += 1
        return iterate(*args, **kwargs)  # type: ignore[arg-type]

    def scaled(lin: object) -> tuple[np.ndarray, float]:
        return weights(lin)[0], scales[stage[0]]  # type: ignore[arg-type]

    def standing(problem: refine._Problem, z: np.ndarray, *args: object) -> tuple[np.ndarray, float, object]:
        return np.zeros_like(z), 0.0, refine.LineMapping(problem.full(z), problem.data.tau_s, problem.free)

    monkeypatch.setattr(refine, "_iterate", counted)
    monkeypatch.setattr(refine, "weights", scaled)
    monkeypatch.setattr(refine, "_damped_step", standing)
    config = refine.DenseConfig(tolerance=1e-12)
    assert (config.max_iterations, config.fine_iterations, refine.GIVE_UP_STEPS) == (15, 6, 8)
    fit = refine.refine_dense(data, mapping.x, config=config, noise=scene.scanner.noise, give_up_scale=9.0)
    assert fit.given_up == given_up and fit.iterations == steps
    if given_up:
        assert fit.given_up_scale == 50.0 and stage[0] == given_up - 1
