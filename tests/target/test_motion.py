from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tumblescan.geometry.rotations import rotate, rotation_matrix
from tumblescan.target.motion import Motion, canonical_params, predict, to_reference, transport

angles = st.floats(-10, 10, allow_nan=False)
params = st.lists(st.floats(-5, 5, allow_nan=False), min_size=9, max_size=9).map(np.array)


@given(a=angles, b=angles, angle=angles)
def test_rotation_matrix_is_orthonormal_and_matches_rodrigues(a: float, b: float, angle: float) -> None:
    axis = np.array([np.cos(a) * np.sin(b), np.sin(a) * np.sin(b), np.cos(b)])
    R = rotation_matrix(axis, angle)
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    v = np.array([0.3, -1.2, 2.0])
    assert np.allclose(R @ v, rotate(axis, np.asarray(angle), v), atol=1e-12)
    assert np.allclose(R @ axis, axis, atol=1e-12)


@settings(max_examples=50)
@given(x=params)
def test_canonical_params_describe_the_same_motion(x: np.ndarray) -> None:
    c = canonical_params(x)
    assert c[2] >= 0 and c[5] >= 0
    assert 0 <= c[1] <= np.pi and 0 <= c[4] <= np.pi
    rng = np.random.default_rng(0)
    pts, tau = rng.normal(size=(20, 3)) * 5, rng.uniform(-3, 3, 20)
    assert np.allclose(predict(x, pts, tau), predict(c, pts, tau), atol=1e-9)


@settings(max_examples=50)
@given(x=params)
def test_forward_then_backward_is_identity(x: np.ndarray) -> None:
    rng = np.random.default_rng(1)
    pts, tau = rng.normal(size=(30, 3)) * 10, rng.uniform(-5, 5, 30)
    assert np.allclose(to_reference(x, predict(x, pts, tau), tau), pts, atol=1e-9)
    assert np.allclose(transport(x, pts, tau, tau), pts, atol=1e-9)


def test_spin_axis_precesses_about_the_precession_axis() -> None:
    m = Motion.from_degrees(
        spin_axis=(1, 0, 1), spin_rate_deg_s=20, precession_axis=(0, 0, 1), precession_rate_deg_s=90, center_m=(0, 0, 5)
    )
    # A quarter precession period later the spin axis has turned 90 deg about z.
    assert np.allclose(m.spin_axis_at(1.0), np.array([0, 1, 1]) / np.sqrt(2), atol=1e-12)
    assert m.nutation_angle_deg() == pytest.approx(45.0)


def test_motion_of_points_on_the_spin_axis_through_the_centre_is_precession_only() -> None:
    m = Motion.from_degrees(spin_axis=(0, 0, 1), spin_rate_deg_s=30, precession_axis=(0, 0, 1), center_m=(1, 2, 3))
    # No precession: points on the spin axis stay put, others turn at the spin rate.
    on_axis = np.array([[1.0, 2.0, 10.0]])
    assert np.allclose(m.position(on_axis, [2.0]), on_axis)
    off = np.array([[2.0, 2.0, 3.0]])
    assert np.allclose(m.position(off, [3.0]), [[1.0, 3.0, 3.0]], atol=1e-12)


def test_canonical_flips_negative_rates() -> None:
    m = Motion.from_degrees(
        spin_axis=(0, 0, 1), spin_rate_deg_s=-10, precession_axis=(1, 0, 0), precession_rate_deg_s=-5
    )
    c = m.canonical()
    assert c.spin_rate_rad_s > 0 and c.precession_rate_rad_s > 0
    assert np.allclose(c.spin_axis, (0, 0, -1)) and np.allclose(c.precession_axis, (-1, 0, 0))
