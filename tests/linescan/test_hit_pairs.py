"""The benches on the hits the surfels leave out (``hit_pairs``, ``hit_bias``): the groups on
noise-free frames, their targets' shared noise, each surfel's majority face, the interval designs
are compared by, and the true faces' planes."""

from __future__ import annotations

import numpy as np
from bench.linescan.hit_bias import true_planes
from bench.linescan.hit_pairs import HitGroups, hit_groups, majority_face, paired_interval, random_effect_system
from bench.linescan.truth import dense_data

from tumblescan import Scanner, Scene, simulate_frames
from tumblescan.linescan.dense.mapping import LineMapping
from tumblescan.linescan.dense.matching import Linearized
from tumblescan.linescan.dense.surfels import build_surfels

from ..conftest import motion_for


def test_on_noise_free_frames_the_left_out_hits_lie_on_their_targets_planes() -> None:
    motion = motion_for(1, distance_m=50.0)
    scene = Scene(scanner=Scanner(lines=160, pixels=160), noise=False)
    sim = simulate_frames(motion, scene, seed=1)
    T = float(sim.t_s.min())
    noise = scene.scanner.noise
    data = dense_data(sim, T, noise.range_sigma_m)
    mapping = LineMapping(motion.at_reference(T).params(), data.tau_s, tuple(range(9)))
    surf = build_surfels(data, mapping, noise)
    found, share = hit_groups(data, mapping, surf, noise)
    groups = found.lin
    left_out = float(np.mean(~surf.planar[surf.point_cell]))
    assert 0.02 < share <= left_out
    assert np.all(groups.var > 0) and groups.J.shape == (len(groups.r), 9)
    # The box's faces are exact planes, so the groups lie on their targets' planes within what
    # the surfels' own build leaves (their normals take out a noise these frames do not have:
    # tenths of a millimetre), a twentieth of one hit's 2 cm; a few along edges take a
    # neighbour face's surfel (millimetres, within the gate's 3 sigmas).
    q50, q95 = np.quantile(np.abs(groups.r), [0.5, 0.95])
    assert q50 < 5e-4 and q95 < 2e-3


def test_a_surfels_face_is_the_one_most_of_its_points_lie_on() -> None:
    point_cell = np.array([0, 0, 0, 1, 1, 2, 2, 2, 2])
    hit_face = np.array([3, 5, 5, 0, 0, -1, -1, -1, 4])
    assert majority_face(point_cell, hit_face, 4).tolist() == [5, 0, -1, -2]


def test_the_interval_is_over_the_cases() -> None:
    rng = np.random.default_rng(0)
    base = rng.normal(size=(20, 4))
    lo, hi = paired_interval(0.5 * base, base, rng)
    assert hi < 0 < lo + 1.0
    # The same errors in another order of the cases: no difference either way.
    lo, hi = paired_interval(base[::-1], base, rng)
    assert lo < 0 < hi


def test_a_targets_shared_noise_weighs_its_groups_as_one() -> None:
    rng = np.random.default_rng(2)
    n, k = 400, 3
    target = rng.integers(0, 40, n)
    J = rng.normal(size=(n, k))
    r = rng.normal(size=n)
    own = rng.uniform(0.5, 2.0, n)

    def system(shared: float, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return random_effect_system(HitGroups(Linearized(r, J, own + shared), target, np.full(n, shared)))

    # Without shared noise: weighted least squares.
    H, g = system(1e-12, r)
    np.testing.assert_allclose(H, J.T @ (J / own[:, None]), rtol=1e-6)
    np.testing.assert_allclose(g, J.T @ (r / own), rtol=1e-6)
    # With a shared noise far larger than the groups' own, a common offset of one target's
    # groups is that noise, and tells nothing.
    H, g = system(1e8, r)
    shifted = r + np.where(target == 7, 5.0, 0.0)
    np.testing.assert_allclose(system(1e8, shifted)[1], g, atol=1e-5)


def test_the_true_planes_face_the_sensor() -> None:
    # Two faces of a box seen from the origin: the floor below (y = 2) and a wall ahead (z = 40).
    rng = np.random.default_rng(4)
    floor = np.column_stack([rng.uniform(-1, 1, 50), np.full(50, 2.0), rng.uniform(35, 39, 50)])
    wall = np.column_stack([rng.uniform(-1, 1, 50), rng.uniform(-1, 1, 50), np.full(50, 40.0)])
    face = np.repeat([0, 1], 50)
    normals, offsets = true_planes(face, np.vstack([floor, wall]), np.zeros((100, 3)))
    np.testing.assert_allclose(normals, [[0.0, -1.0, 0.0], [0.0, 0.0, -1.0]], atol=1e-12)
    np.testing.assert_allclose(offsets, [-2.0, -40.0], atol=1e-9)
