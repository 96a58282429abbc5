"""The draw-bias bench (``bench/linescan/draw_bias.py``): the surfels' roles on the box's frames
and the bias statistics over draws."""

from __future__ import annotations

import argparse

import numpy as np
import pytest
from bench.common import ShapeCase, add_cases, shape_case
from bench.linescan.dense_bound import face_of_hits, last_stage_matches
from bench.linescan.draw_bias import bias_table, subset_rows, surfel_roles
from bench.linescan.reuse_diag import at_truth

from tumblescan import Scanner, Scene

from ..conftest import motion_for


def test_surfel_roles_on_the_box() -> None:
    motion = motion_for(1, distance_m=50.0)
    scene = Scene(scanner=Scanner(lines=160, pixels=160), noise=False)
    sim, data, mapping, surf = at_truth(motion, scene, 1)
    kept = np.ones(len(sim.xyz_m), dtype=bool) if data.kept is None else data.kept
    face = face_of_hits(scene, motion, sim.reference_m)[0][kept]
    roles = surfel_roles(data, surf, face)
    pc = surf.point_cell
    # A pure surfel's points lie on one face; an interior one is pure, and so are its neighbours,
    # on its face; a receiver holds points of another cell, and no other surfel does.
    for s in np.flatnonzero(roles.pure)[:200]:
        assert len(np.unique(face[pc == s])) == 1
    assert np.all(roles.pure[roles.interior])
    inner = np.flatnonzero(roles.interior)
    assert len(inner) > 100
    nb = data.neighbours[inner]
    assert np.all(nb >= 0) and np.all(roles.pure[nb])
    took = np.zeros(len(surf.planar), dtype=bool)
    took[pc[pc != data.cell]] = True
    assert np.array_equal(roles.receiver, took) and 0 < took.sum() < roles.pure.sum()
    # The hand-over gives only to planar surfels, and only the cells that are not planar give.
    gave = np.unique(data.cell[pc != data.cell])
    assert np.all(surf.planar[roles.receiver]) and not np.any(surf.planar[gave])
    # Some planar surfels lie beside an edge or the outline: not every pair is interior.
    matches, _ = last_stage_matches(data, mapping, surf, scene.scanner.noise)
    rows = subset_rows(roles, matches)
    assert rows["all"].all() and 0 < rows["interior"].sum() < rows["pure"].sum() <= len(matches.src)
    assert not np.any(rows["no receivers"] & (roles.receiver[matches.src] | roles.receiver[matches.dst]))


def test_bias_table_reads_a_known_offset() -> None:
    rng = np.random.default_rng(3)
    sd = np.array([1.0, 2.0, 0.5])
    steps = rng.normal(size=(400, 3)) * sd + np.array([0.0, 1.0, 0.0])
    out = bias_table(steps, bound_sd=np.array([1.0, 1.0, 0.5]))
    # No bias: within 3 standard errors; an offset of half the spread over 400 draws: ~10.
    assert abs(out["bias_over_se"][0]) < 3 and abs(out["bias_over_se"][2]) < 3
    assert 7 < out["bias_over_se"][1] < 13
    np.testing.assert_allclose(out["sd_over_bound"], [1.0, 2.0, 1.0], rtol=0.1)
    np.testing.assert_allclose(out["bias_over_bound"][1], 1.0, atol=0.3)


def test_the_benches_read_a_case_as_shape_range_seed_and_name_a_malformed_one() -> None:
    parser = argparse.ArgumentParser()
    add_cases(parser, ShapeCase("box", 50, 14))
    assert parser.parse_args([]).cases == [ShapeCase("box", 50.0, 14)]
    (case,) = parser.parse_args(["--cases", "long-array:100:31"]).cases
    assert case == ShapeCase("long-array", 100.0, 31) and str(case) == "long-array:100:31"
    for bad in ("hubble:fifty:2", "hubble:50", "hubble:50:2:1"):
        with pytest.raises(argparse.ArgumentTypeError, match=f"'{bad}' is not shape:range_m:seed"):
            shape_case(bad)
