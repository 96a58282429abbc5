"""The bench's dense Cramer-Rao bound on any shape: mesh faces as the nuisance planes."""

from __future__ import annotations

import numpy as np
import pytest
from bench.linescan.dense_bound import (
    COPLANAR_DEG,
    COPLANAR_M,
    bound_covariances,
    box_face_of_hits,
    dense_bound,
    face_of_hits,
    mesh_faces,
    normal_of_triangle,
    share_within,
)

from tumblescan import Scanner, Scene, simulate_frames
from tumblescan.target.shape import SatelliteShape
from tumblescan.target.shapes import PARAMETRIC, _Parts

from ..conftest import motion_for


def _faces(mesh: object) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    vertices = np.asarray(mesh.vertices, dtype=np.float64)  # type: ignore[attr-defined]
    triangles = np.asarray(mesh.triangles, dtype=np.int64)  # type: ignore[attr-defined]
    face, normals = mesh_faces(vertices, triangles)
    return vertices, triangles, face, normals


def test_the_box_mesh_has_the_boxes_faces() -> None:
    _, _, face, normals = _faces(SatelliteShape().mesh())
    # 3 boxes of 6 faces, 2 triangles each: coplanar faces of different boxes stay apart.
    assert len(normals) == 18
    assert np.all(np.bincount(face) == 2)


def test_an_octagonal_prism_is_eight_sides_and_two_caps() -> None:
    parts = _Parts()
    parts.cylinder(1.6, 3.0, (0, 0, 1), (0, 0, 0), resolution=8)
    _, _, face, normals = _faces(parts.mesh)
    # Open3D splits each side in 4 along the height (8 triangles) and fans each cap (8).
    assert len(normals) == 10
    assert np.all(np.bincount(face) == 8)
    sides = normals[np.abs(normals[:, 2]) < 1e-9]
    assert len(sides) == 8
    assert np.allclose(np.sort(np.degrees(np.arctan2(sides[:, 1], sides[:, 0])) % 360) % 45, 22.5)


@pytest.mark.parametrize("name", [*PARAMETRIC, "fine cylinder"])
def test_every_triangle_lies_in_its_face_plane(name: str) -> None:
    if name == "fine cylinder":
        # Facets 0.36 deg apart: neighbours pass the tolerance, yet the tube must not become one
        # plane (each triangle is tested against the face's first triangle, not its neighbour).
        parts = _Parts()
        parts.cylinder(2.0, 4.0, (0, 0, 1), (0, 0, 0), resolution=1000)
        mesh = parts.mesh
    else:
        mesh = PARAMETRIC[name]().mesh()
    vertices, triangles, face, normals = _faces(mesh)
    tri_normal = normal_of_triangle(vertices, triangles)
    flat = np.any(tri_normal != 0, axis=1)
    cos = np.einsum("ti,ti->t", tri_normal[flat], normals[face[flat]])
    assert np.all(cos >= np.cos(np.radians(COPLANAR_DEG)) - 1e-12)
    # Every corner within the tolerance of its face's plane (that of its first triangle).
    for f in np.unique(face[flat]):
        corners = vertices[triangles[face == f]].reshape(-1, 3)
        assert np.ptp(corners @ normals[f]) <= 2 * COPLANAR_M + 1e-9
    if name == "fine cylinder":
        # A facet and its two neighbours at most (0.36 deg either side; 8 triangles a facet).
        sides = np.flatnonzero(np.abs(normals[:, 2]) < 1e-9)
        assert np.bincount(face, minlength=len(normals))[sides].max() <= 3 * 8


def test_the_mesh_faces_bound_of_the_box_is_the_box_faces_bound() -> None:
    motion = motion_for(3, distance_m=50.0)
    scene = Scene(scanner=Scanner(lines=160, pixels=160))
    sim = simulate_frames(motion, scene, seed=3)
    reference_time_s = float(np.median(sim.t_s))
    boxes = box_face_of_hits(scene, motion, sim.reference_m)
    mesh = face_of_hits(scene, motion, sim.reference_m)
    # Every hit lies on a face either way, and the faces agree but within a millimetre of an edge.
    assert np.all(boxes[0] >= 0) and np.all(mesh[0] >= 0)
    pairs, count = np.unique(np.stack([boxes[0], mesh[0]]), axis=1, return_counts=True)
    main = [pairs[1][pairs[0] == f][np.argmax(count[pairs[0] == f])] for f in np.unique(pairs[0])]
    agree = sum(count[pairs[0] == f].max() for f in np.unique(pairs[0]))
    assert agree >= 0.999 * len(sim.t_s)
    # A face seen beyond its edges (100 hits or more) is one face of the mesh, and no other's.
    seen = np.bincount(boxes[0]) >= 100
    assert len(set(np.asarray(main)[seen[np.unique(pairs[0])]])) == np.count_nonzero(seen)
    by_box = dense_bound(motion, scene, sim, reference_time_s, faces=boxes)
    by_mesh = dense_bound(motion, scene, sim, reference_time_s, faces=mesh)
    for key in ("spin_axis_deg", "spin_rate_deg_s", "precession_axis_deg", "precession_rate_deg_s", "center_m"):
        assert by_mesh[key] == pytest.approx(by_box[key], rel=0.03), key
    assert by_mesh["faces"] == by_box["faces"]


def test_the_bound_of_the_rates_does_not_depend_on_the_reference_time() -> None:
    # The rates, the precession axis and the centre are the same whatever time the motion is
    # stated at, and so are their bounds; the faces' normals must be turned to that time.
    motion = motion_for(5, distance_m=100.0)
    scene = Scene(scanner=Scanner(lines=160, pixels=160))
    sim = simulate_frames(motion, scene, seed=5)
    faces = face_of_hits(scene, motion, sim.reference_m)
    first, middle = (dense_bound(motion, scene, sim, float(t), faces=faces) for t in (sim.t_s[0], np.median(sim.t_s)))
    for key in ("spin_rate_deg_s", "precession_axis_deg", "precession_rate_deg_s", "center_m"):
        assert middle[key] == pytest.approx(first[key], rel=1e-6), key


def test_knowing_the_shape_bounds_below_the_planes_model() -> None:
    # The exact shape with only its pose unknown is a special case of free face planes (a pose
    # moves every plane), so its bound is below theirs in every direction; knowing the pose too
    # would be below that.
    motion = motion_for(2, distance_m=50.0)
    scene = Scene(scanner=Scanner(lines=160, pixels=160))
    sim = simulate_frames(motion, scene, seed=2)
    b = bound_covariances(motion, scene, sim, float(np.median(sim.t_s)))
    scale = np.sqrt(np.diag(b.facets))
    gap = (b.facets - b.known_shape) / np.outer(scale, scale)
    assert np.linalg.eigvalsh(gap).min() > -1e-9
    assert np.trace(gap) > 0.01  # and the planes' own parameters cost something
    assert b.faces >= 6 and b.points > 1000  # of the 18


def test_share_within_counts_a_gaussian_estimate_against_the_limits() -> None:
    # Spin rate of 1-sigma = the limit: |z| <= 1 for 68.3 %; a spin axis of isotropic 1-sigma
    # s per angle (on the equator, where an angle is an arc) errs by a Rayleigh angle, within
    # L = s sqrt(2) for 1 - e^-1 = 63.2 %; the other parameters far inside their limits.
    x = np.array([0.3, np.pi / 2, 0.05, 1.0, 0.7, 0.02, 0.0, 0.0, 50.0])
    tiny = 1e-12
    rate_limit, axis_limit = 0.05, 0.1
    cov = np.diag([tiny, tiny, np.radians(rate_limit) ** 2, tiny, tiny, tiny, 1.0, 1.0, 1.0])
    assert share_within(x, cov, axis_limit, rate_limit) == pytest.approx(0.683, abs=0.01)
    s = np.radians(axis_limit) / np.sqrt(2)
    cov = np.diag([s**2, s**2, tiny, tiny, tiny, tiny, 1.0, 1.0, 1.0])
    assert share_within(x, cov, axis_limit, rate_limit) == pytest.approx(1 - np.exp(-1), abs=0.01)
