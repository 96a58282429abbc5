"""The bench's per-hit design against planes of the map: its corrected plane fit, its optimum on
noise-free frames, and the variance gradient its errors-in-variables correction rests on."""

from __future__ import annotations

from functools import cache

import numpy as np
from bench.linescan.dense_bound import face_of_hits, majority_face
from bench.linescan.patch_potential import Patches, PatchFit, cut_patches, gate_hits, noise_product, plane_fit
from bench.linescan.real_shapes import shape_named
from bench.linescan.reuse_diag import at_truth
from bench.linescan.truth import dense_data

from tumblescan import Scanner, Scene, random_motion, simulate_frames
from tumblescan.geometry.rotations import axis_from_angles
from tumblescan.linescan.dense.data import DenseData
from tumblescan.linescan.dense.mapping import LineMapping
from tumblescan.linescan.dense.surfels import build_surfels, normal_variance
from tumblescan.linescan.sensor import SensorNoise, perpendiculars

from ..conftest import motion_for


def test_the_corrected_plane_fit_takes_out_the_tilt_the_shared_noise_gives() -> None:
    # A plane at 50 m seen 60 deg from head-on: range noise (2 cm along the sight) moves a hit
    # along the plane and off it at once, so least squares tilts the plane; the noise's moments
    # taken out, the tilt is the true one.
    rng = np.random.default_rng(3)
    noise = SensorNoise()
    sight = np.array([0.0, 0.0, 1.0])
    normal = np.array([np.sin(np.radians(60.0)), 0.0, -np.cos(np.radians(60.0))])
    e1, e2 = (v[0] for v in perpendiculars(normal[None, :]))
    n = 200_000
    uv = rng.uniform(-1.0, 1.0, (n, 2))
    true = 50.0 * sight + uv[:, :1] * e1 + uv[:, 1:] * e2
    xyz = noise.sample(true, rng)
    d = xyz - 50.0 * sight
    w, uv_seen = d @ normal, np.column_stack([d @ e1, d @ e2])
    rows = np.ones((n, 1))
    var = noise_product(noise, xyz, rows * normal, rows * normal)
    cov_uv = np.empty((n, 2, 2))
    for j, a in enumerate((e1, e2)):
        for k, b in enumerate((e1, e2)):
            cov_uv[:, j, k] = noise_product(noise, xyz, rows * a, rows * b)
    cov_uv_w = np.column_stack([noise_product(noise, xyz, rows * a, rows * normal) for a in (e1, e2)])
    patch = np.zeros(n, dtype=np.int64)
    raw, normal_matrix = plane_fit(w, uv_seen, 1.0 / var, patch, 1, None)
    fixed, _ = plane_fit(w, uv_seen, 1.0 / var, patch, 1, (cov_uv, cov_uv_w))
    slope_se = np.sqrt(np.diag(np.linalg.inv(normal_matrix[0]))[1:])  # the slopes' standard errors
    assert np.max(np.abs(raw[0, 1:]) / slope_se) > 5.0
    assert np.all(np.abs(fixed[0, 1:]) / slope_se < 3.0)


@cache
def _box() -> tuple[DenseData, LineMapping, SensorNoise, Patches]:
    """Noise-free frames of the box at 50 m, at the true motion, and their patches."""
    motion = motion_for(1, distance_m=50.0)
    scene = Scene(scanner=Scanner(lines=160, pixels=160), noise=False)
    sim = simulate_frames(motion, scene, seed=1)
    T = float(sim.t_s.min())
    data = dense_data(sim, T, scene.scanner.noise.range_sigma_m)
    mapping = LineMapping(motion.at_reference(T).params(), data.tau_s, tuple(range(9)))
    surf = build_surfels(data, mapping, scene.scanner.noise)
    planar = np.asarray(surf.planar[surf.point_cell])
    normal_T = np.einsum("nij,nj->ni", mapping.Rt[surf.line], surf.normal_obs)[surf.point_cell]
    patches = cut_patches(mapping.apply(data.xyz_m, data.line), normal_T, planar, 6 * data.surfel_m)
    return data, mapping, scene.scanner.noise, patches


def test_on_noise_free_frames_the_per_hit_optimum_is_the_truth() -> None:
    data, mapping, noise, patches = _box()
    assert np.mean(patches.used) > 0.5
    x0 = mapping.x
    # Started a little off the truth, the steps come back to it (the raw design: the corrections
    # take out noise moments that noise-free frames do not have).
    start = x0 + np.array([1e-3, -1e-3, 1e-4, 1e-3, 1e-3, -1e-4, 0.0, 0.0, 0.0])
    x, _, _, _ = PatchFit(data, noise, patches, corrected=False).optimum(start, 4)
    axis_off = [
        np.degrees(np.arccos(np.clip(axis_from_angles(x[a], x[a + 1]) @ axis_from_angles(x0[a], x0[a + 1]), -1, 1)))
        for a in (0, 3)
    ]
    assert max(axis_off) < 1e-3  # deg
    assert np.max(np.abs(np.degrees(x[[2, 5]] - x0[[2, 5]]))) < 1e-4  # deg/s


def test_the_variance_gradient_is_the_variance_s_derivative() -> None:
    # The errors-in-variables correction rests on d var / dx: against central differences of
    # the variance along each patch normal turned into its hit's sensor frame by the motion.
    data, mapping, noise, patches = _box()
    idx = np.flatnonzero(patches.used)[::50]
    analytic = PatchFit(data, noise, patches, corrected=True).variance_gradient(mapping, idx)
    n_T = patches.normal[patches.patch[idx]]

    def variance(x: np.ndarray) -> np.ndarray:
        m = LineMapping(x, data.tau_s, tuple(range(9)))
        n_obs = np.einsum("nij,ni->nj", m.Rt[data.line[idx]], n_T)
        return normal_variance(noise, data.xyz_m[idx], n_obs)

    h = 1e-6
    for j in range(9):
        step = np.zeros(9)
        step[j] = h
        numeric = (variance(mapping.x + step) - variance(mapping.x - step)) / (2 * h)
        scale = np.max(np.abs(analytic))
        assert np.allclose(analytic[:, j], numeric, rtol=1e-4, atol=1e-5 * scale), j
    assert np.max(np.abs(analytic[:, :6])) > 0  # the turning parameters move it; the centre does not


def test_the_gate_leaves_each_hit_on_a_plane_facing_its_sensor_so_a_plates_back_takes_none() -> None:
    # The long array is a plate 5 cm thick: its back lies 2.5 range sigmas behind its front, so
    # a front hit pushed back by its noise lay nearer the back's plane in sigmas and was gated
    # there, then dropped with that patch's other face: the front kept a noise-selected sample
    # (its hits' mean 0.04 sigma off the face, 10 standard errors, on this motion).
    motion = random_motion(np.random.default_rng(3), distance_m=100.0)
    scene = Scene(scanner=Scanner(), shape=shape_named("long-array"))
    noise = scene.scanner.noise
    sim, data, mapping, surf = at_truth(motion, scene, 1003)
    xyz_T, true_T = mapping.apply(data.xyz_m, data.line), mapping.apply(sim.xyz_true_m, data.line)
    planar = np.asarray(surf.planar[surf.point_cell])
    cell_normal_T = np.einsum("nij,nj->ni", mapping.Rt[surf.line], surf.normal_obs)[surf.point_cell]
    cube_m = 6.0 * data.surfel_m
    patches = cut_patches(xyz_T, cell_normal_T, planar, cube_m)
    gated = gate_hits(PatchFit(data, noise, patches, corrected=False), mapping, xyz_T, cube_m)
    # Every hit on a plane that faces its sensor.
    k = gated.patch[gated.used]
    sight = mapping.apply(np.zeros((len(k), 3)), data.line[gated.used]) - xyz_T[gated.used]
    assert np.all(np.einsum("ni,ni->n", gated.normal[k], sight) > 0)
    # The array's faces keep a fair sample: the hits joined to a patch of their own face lie on
    # it on average, within 4 standard errors.
    face = face_of_hits(scene, motion, sim.reference_m)[0]
    own = gated.used & (
        face == majority_face(gated.patch[gated.used], face[gated.used], len(gated.centre))[np.maximum(gated.patch, 0)]
    )
    n = gated.normal[gated.patch[own]]
    z = np.einsum("ni,ni->n", xyz_T[own] - true_T[own], n) / np.sqrt(
        normal_variance(noise, data.xyz_m[own], np.einsum("nij,ni->nj", mapping.Rt[data.line[own]], n))
    )
    assert len(z) > 100_000 and abs(z.mean()) < 4 / np.sqrt(len(z))
