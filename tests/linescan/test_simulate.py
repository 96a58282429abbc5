from __future__ import annotations

import numpy as np

from tumblescan import Scanner, Scene, simulate_frames, simulate_tracks
from tumblescan.linescan.sensor import azimuth_elevation

from ..conftest import motion_for


def test_tracks_are_corners_seen_at_their_scan_line_time() -> None:
    motion = motion_for(2)
    scene = Scene(noise=False)
    tracks, truth = simulate_tracks(motion, scene, seed=2)
    line_times = scene.scanner.line_times_s(scene.frames)
    # Every observation happens at a line time of its frame.
    assert np.all(np.isclose(line_times[tracks.frame], tracks.t_s[:, None], atol=1e-12).any(axis=1))
    # Noise-free observations are exactly the moving corners.
    corner = np.array([int(tracks.track_ids[k][1:]) - 1 for k in tracks.track])
    expected = motion.position(truth.corners_reference_m[corner], tracks.t_s)
    assert np.allclose(tracks.xyz_m, expected, atol=1e-9)
    # ... inside the field of view, once per frame per corner.
    az, el = azimuth_elevation(tracks.xyz_m)
    half = np.radians(5.0) + 1e-9
    assert np.all(np.abs(az) <= half) and np.all(np.abs(el) <= half)
    assert len({(f, k) for f, k in zip(tracks.frame, tracks.track, strict=True)}) == len(tracks)


def test_corners_outside_the_field_of_view_are_missing_not_invented() -> None:
    # At 50 m the 10 deg field covers ~8.7 m of a 14.4 m satellite: some corners leave it.
    motion = motion_for(0)
    tracks, _ = simulate_tracks(motion, Scene(noise=False, occlusion=False), seed=0)
    per_frame = np.bincount(tracks.frame)
    assert per_frame.max() < 16
    # From far away the whole target fits and, without occlusion, every corner is seen.
    far = motion_for(0, distance_m=300.0)
    tracks_far, _ = simulate_tracks(far, Scene(noise=False, occlusion=False), seed=0)
    assert np.all(np.bincount(tracks_far.frame) == 16)


def test_noise_has_the_declared_range_and_angle_sigma() -> None:
    motion = motion_for(5, distance_m=300.0)
    scene = Scene(occlusion=False, frames=200)
    tracks, truth = simulate_tracks(motion, scene, seed=5)
    d = tracks.xyz_m - truth.xyz_true_m
    u = truth.xyz_true_m / np.linalg.norm(truth.xyz_true_m, axis=1, keepdims=True)
    along = np.sum(d * u, axis=1)
    across = np.linalg.norm(d - along[:, None] * u, axis=1) / np.linalg.norm(truth.xyz_true_m, axis=1)
    assert abs(np.std(along) / 0.02 - 1) < 0.1
    # |across| is Rayleigh with sigma = angle sigma: its RMS is sqrt(2) sigma.
    sigma = 36 * np.pi / 180 / 3600
    assert abs(np.sqrt(np.mean(across**2)) / (np.sqrt(2) * sigma) - 1) < 0.1


def test_dense_frames_are_exact_ray_casts_with_ground_truth(small_scanner: Scanner) -> None:
    motion = motion_for(1)
    scene = Scene(scanner=small_scanner, frames=4, noise=False)
    cloud = simulate_frames(motion, scene, seed=1)
    assert len(cloud.t_s) > 1000
    # Each point's time is its line's time, and it lies on its line's ray.
    assert np.allclose(cloud.t_s, scene.scanner.line_times_s(4)[cloud.frame, cloud.line])
    dirs = small_scanner.ray_directions()[cloud.line, cloud.pixel]
    rng_m = np.linalg.norm(cloud.xyz_m, axis=1)
    assert np.allclose(cloud.xyz_m, dirs * rng_m[:, None], atol=1e-9)
    # The reference cloud moved with the true motion gives the observations.
    assert np.allclose(motion.position(cloud.reference_m, cloud.t_s), cloud.xyz_m, atol=1e-9)
    # Reference points lie on the surface, to the float32 precision Open3D casts with at 50 m.
    import open3d as o3d

    mesh = scene.shape.mesh()
    mesh.vertices = o3d.utility.Vector3dVector(scene.body_points(motion, np.asarray(mesh.vertices)))
    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    points = o3d.core.Tensor(cloud.reference_m.astype(np.float32))  # type: ignore[call-overload]
    dist = rc.compute_distance(points).numpy()
    assert np.max(dist) < 1e-3 and np.median(dist) < 1e-5


def test_simulation_is_reproducible_from_its_seed(small_scanner: Scanner) -> None:
    motion = motion_for(3)
    scene = Scene(scanner=small_scanner, frames=4)
    a, b = simulate_frames(motion, scene, seed=9), simulate_frames(motion, scene, seed=9)
    assert np.array_equal(a.xyz_m, b.xyz_m)
    c = simulate_frames(motion, scene, seed=10)
    assert not np.array_equal(a.xyz_m, c.xyz_m)
