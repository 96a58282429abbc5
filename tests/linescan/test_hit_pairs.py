"""The benches on the hits the surfels leave out (``hit_pairs``, ``hit_bias``): the groups on
noise-free frames and their Jacobian, each group's majority face, the interval designs are
compared by, and the true faces' planes."""

from __future__ import annotations

import numpy as np
from bench.linescan.dense_bound import majority_face
from bench.linescan.hit_bias import true_planes
from bench.linescan.hit_pairs import linearize_hits, match_hits, paired_interval
from bench.linescan.reuse_diag import at_truth

from tumblescan import Scanner, Scene
from tumblescan.linescan.dense.mapping import LineMapping

from ..conftest import motion_for


def test_on_noise_free_frames_the_left_out_hits_lie_on_their_targets_planes() -> None:
    motion = motion_for(1, distance_m=50.0)
    scene = Scene(scanner=Scanner(lines=160, pixels=160), noise=False)
    noise = scene.scanner.noise
    _, data, mapping, surf = at_truth(motion, scene, 1)
    matches, share = match_hits(data, mapping, surf, noise)
    groups = linearize_hits(data, mapping, surf, noise, matches)
    assert share > 0.02 and len(groups.r) == len(matches.cell) > 1000
    # The box's faces are exact planes, so the groups lie on their targets' planes within what
    # the surfels' own build leaves (their normals take out a noise these frames do not have:
    # tenths of a millimetre), a twentieth of one hit's 2 cm; a few along edges take a
    # neighbour face's surfel (millimetres, within the gate's 3 sigmas).
    q50, q95 = np.quantile(np.abs(groups.r), [0.5, 0.95])
    assert q50 < 5e-4 and q95 < 3e-3
    # Their Jacobian is the residuals' derivative with each target's normal held (as the fit's
    # pairs hold theirs), for the same hits on the same targets.
    n0 = mapping.rotate(surf.normal_obs[matches.target], surf.line[matches.target])
    k = np.bincount(matches.group)

    def residuals(x: np.ndarray) -> np.ndarray:
        moved = LineMapping(x, data.tau_s, mapping.free)
        d = moved.apply(data.xyz_m[matches.hit], data.line[matches.hit]) - moved.apply(
            surf.anchor_obs[matches.target], surf.line[matches.target]
        )
        return np.bincount(matches.group, np.einsum("ni,ni->n", n0, d)) / k

    np.testing.assert_allclose(residuals(mapping.x), groups.r, atol=1e-12)
    h = 1e-6
    for j in range(9):
        dx = np.zeros(9)
        dx[j] = h
        derivative = (residuals(mapping.x + dx) - residuals(mapping.x - dx)) / (2 * h)
        np.testing.assert_allclose(derivative, groups.J[:, j], rtol=1e-5, atol=1e-6)


def test_a_groups_face_is_the_one_most_of_its_members_lie_on() -> None:
    member_of = np.array([0, 0, 0, 1, 1, 2, 2, 2, 2, 3, 3])
    face = np.array([3, 5, 5, 0, 0, -1, -1, -1, 4, 1, 2])
    # Unknown faces (-1) do not count; a tie goes to the larger index; a group with none: -1.
    assert majority_face(member_of, face, 5).tolist() == [5, 0, 4, 2, -1]


def test_the_interval_is_over_the_cases_and_paired() -> None:
    rng = np.random.default_rng(0)
    base = np.abs(rng.normal(size=(20, 4)))
    # One design 1 % above the other in every case: paired, the difference is that 1 % in every
    # resample (resampling each design's cases apart would spread it by tenths).
    lo, hi = paired_interval(1.01 * base, base, rng)
    rms = float(np.sqrt(np.mean(base**2)))
    assert 0.005 * rms < lo <= hi < 0.015 * rms
    # The same errors in another order of the cases: no difference either way.
    lo, hi = paired_interval(base[::-1], base, rng)
    assert lo < 0 < hi


def test_the_true_planes_face_the_sensor() -> None:
    # Two faces of a box seen from the origin: the floor below (y = 2) and a wall ahead (z = 40).
    rng = np.random.default_rng(4)
    floor = np.column_stack([rng.uniform(-1, 1, 50), np.full(50, 2.0), rng.uniform(35, 39, 50)])
    wall = np.column_stack([rng.uniform(-1, 1, 50), rng.uniform(-1, 1, 50), np.full(50, 40.0)])
    face = np.repeat([0, 1], 50)
    normals, offsets = true_planes(face, np.vstack([floor, wall]), np.zeros((100, 3)))
    np.testing.assert_allclose(normals, [[0.0, -1.0, 0.0], [0.0, 0.0, -1.0]], atol=1e-12)
    np.testing.assert_allclose(offsets, [-2.0, -40.0], atol=1e-9)
