"""Which of two faces' planes a line of sight sees (handover.edge_kind, handover.line_sees), on a ridge
and a valley whose true surface is known."""

from __future__ import annotations

import numpy as np
import pytest

from tumblescan.linescan.dense.handover import edge_kind, line_sees

TILT = np.radians(30.0)


def _faces(ridge: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Two faces 50 m from a sensor at the origin looking along +z, meeting at x = 0: nearest
    the sensor along the edge (a ridge, convex) or farthest (a valley, concave). Unit normals of
    face a (x < 0) and b (x > 0), facing away from the sensor (either sign must do), and their
    centroids 1 m either side of the edge."""
    s = 1.0 if ridge else -1.0
    n_a = np.array([s * np.sin(TILT), 0.0, np.cos(TILT)])
    n_b = np.array([-s * np.sin(TILT), 0.0, np.cos(TILT)])
    c_a = np.array([-1.0, 0.0, 50.0 + s * np.tan(TILT)])
    c_b = np.array([1.0, 0.0, 50.0 + s * np.tan(TILT)])
    return n_a, n_b, c_a, c_b


def _surface_z(x_m: np.ndarray, ridge: bool) -> np.ndarray:
    return 50.0 + (1.0 if ridge else -1.0) * np.abs(x_m) * np.tan(TILT)


@pytest.mark.parametrize("ridge", [True, False])
def test_the_line_of_sight_sees_the_face_the_point_lies_on_whatever_its_range_noise(ridge: bool) -> None:
    n_a, n_b, c_a, c_b = _faces(ridge)
    rng = np.random.default_rng(1)
    x = np.concatenate([rng.uniform(-0.8, 0.8, 2000), np.linspace(-0.002, 0.002, 40)])
    true = np.stack([x, np.zeros_like(x), _surface_z(x, ridge)], axis=1)
    u = true / np.linalg.norm(true, axis=1)[:, None]
    # Range noise of up to 5 sigmas (2 cm) moves each point along its line of sight: within
    # reach of both planes near the edge, yet not where the line meets them.
    p = true + rng.normal(0.0, 0.1, len(x))[:, None] * u
    convex, concave = edge_kind(
        np.tile(n_a, (len(x), 1)), np.tile(-n_b, (len(x), 1)), np.tile(c_b - c_a, (len(x), 1)), u
    )
    assert np.all(convex == ridge) and np.all(concave != ridge)
    delta_a = -((p - c_a) @ n_a) / (u @ n_a)
    delta_b = -((p - c_b) @ n_b) / (u @ n_b)
    # Planes known to a millimetre: the band around the edge is a few millimetres wide.
    sees_a, sees_b = line_sees(delta_a - delta_b, np.full(len(x), 1e-6), convex, concave)
    on_a = x < 0
    assert not np.any(sees_a & sees_b)
    assert np.array_equal(sees_a[np.abs(x) > 0.02], on_a[np.abs(x) > 0.02])
    assert np.array_equal(sees_b[np.abs(x) > 0.02], ~on_a[np.abs(x) > 0.02])
    # Within the band, neither.
    band = np.abs(delta_a - delta_b) < 3e-3
    assert np.any(band) and not np.any((sees_a | sees_b)[band])


def test_planes_one_in_front_of_the_other_meet_at_no_edge() -> None:
    # A panel tilted in front of a wall: the wall's centroid lies behind the panel's plane and
    # the panel's in front of the wall's.
    n_panel = np.array([[np.sin(TILT), 0.0, np.cos(TILT)]])
    n_wall = np.array([[0.0, 0.0, 1.0]])
    gap = np.array([[0.0, 0.0, 3.0]])  # panel at z = 47, wall at z = 50
    convex, concave = edge_kind(n_panel, n_wall, gap, np.array([[0.0, 0.0, 1.0]]))
    assert not convex[0] and not concave[0]
