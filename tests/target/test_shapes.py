"""The shape library: every part where it should be, features on the surface, mesh files
scaled and centred as documented, and scenes that round-trip through JSON."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tumblescan import Scanner, Scene, random_motion, simulate_frames
from tumblescan._open3d import load_open3d
from tumblescan.target.shape import SatelliteShape
from tumblescan.target.shapes import PARAMETRIC, LongArrayShape, MeshFileShape

HUBBLE = Path(__file__).resolve().parents[3] / "shared" / "meshes" / "hubble_illidroid.glb"


def distance_to_mesh(mesh: object, points: np.ndarray) -> np.ndarray:
    o3d = load_open3d()
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    return np.asarray(scene.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy(), dtype=float)


@pytest.mark.parametrize("name", sorted(PARAMETRIC))
def test_parametric_shapes_have_their_features_on_the_surface(name: str) -> None:
    shape = PARAMETRIC[name]()
    corners = shape.corners_m()
    assert len(corners) >= 8
    assert np.max(distance_to_mesh(shape.mesh(), corners)) < 0.01
    assert np.all(shape.extent_m() > 2.0) and np.max(shape.extent_m()) < 30.0


def test_a_mesh_file_is_scaled_to_its_size_and_centred_on_its_surface(tmp_path: Path) -> None:
    o3d = load_open3d()
    box = o3d.geometry.TriangleMesh.create_box(2.0, 1.0, 1.0).translate((5.0, 5.0, 5.0))
    assert o3d.io.write_triangle_mesh(str(tmp_path / "box.ply"), box)
    shape = MeshFileShape(path=str(tmp_path / "box.ply"), size_m=4.0)
    np.testing.assert_allclose(shape.extent_m(), [4.0, 2.0, 2.0], atol=1e-9)
    verts = np.asarray(shape.mesh().vertices)
    np.testing.assert_allclose(verts.min(axis=0), [-2.0, -1.0, -1.0], atol=1e-9)  # the box's surface centroid
    assert np.max(distance_to_mesh(shape.mesh(), shape.corners_m())) < 1e-6


@pytest.mark.skipif(not HUBBLE.is_file(), reason=f"{HUBBLE} is absent (it lives outside the repository)")
def test_the_hubble_mesh_loads_at_its_real_length() -> None:
    shape = MeshFileShape(path=str(HUBBLE), size_m=13.2)
    assert np.max(shape.extent_m()) == pytest.approx(13.2, abs=1e-9)
    assert len(shape.corners_m()) == 24


@pytest.mark.parametrize("name", ["telescope", "octagon-truss"])
def test_simulated_returns_lie_on_the_shape(name: str) -> None:
    motion = random_motion(np.random.default_rng(4), distance_m=60.0)
    scene = Scene(scanner=Scanner(lines=64, pixels=64), shape=PARAMETRIC[name](), noise=False, frames=4)
    cloud = simulate_frames(motion, scene, seed=4)
    assert len(cloud.t_s) > 500
    mesh = scene.shape.mesh()
    body = (cloud.reference_m - np.asarray(motion.center_m)) @ np.asarray(scene.R_body_to_sensor)
    assert np.percentile(distance_to_mesh(mesh, body), 99) < 1e-3


def test_a_scene_round_trips_through_json_and_old_scenes_mean_the_box() -> None:
    scene = Scene(shape=LongArrayShape(array_m=(12.0, 2.0)))
    assert Scene.model_validate_json(scene.model_dump_json()) == scene
    old = scene.model_dump(mode="json") | {"shape": {"bus_m": [3.0, 3.0, 4.0]}}
    assert Scene.model_validate(old).shape == SatelliteShape(bus_m=(3.0, 3.0, 4.0))
