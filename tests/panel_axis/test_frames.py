"""Frames against the paper: the camera rows of eq. 8, ENU->ECEF (M of eq. 3-4), eq. 1 on Table 1."""

from __future__ import annotations

import numpy as np
import pytest

from tumblescan.panel_axis.frames import R_cam_from_enu, R_ecef_from_enu, pitch_yaw_deg


def test_camera_rows_at_zero_roll_are_the_papers() -> None:
    A, E = np.radians(288.0), np.radians(52.0)
    R = R_cam_from_enu(288.0, 52.0)
    assert np.allclose(R[0], [np.cos(A), -np.sin(A), 0])
    assert np.allclose(R[1], [np.sin(E) * np.sin(A), np.sin(E) * np.cos(A), -np.cos(E)])
    assert np.allclose(R[2], [np.cos(E) * np.sin(A), np.cos(E) * np.cos(A), np.sin(E)])
    assert np.allclose(R @ R.T, np.eye(3)) and np.linalg.det(R) == pytest.approx(1.0)


def test_roll_turns_the_image_about_the_line_of_sight() -> None:
    R0, R = R_cam_from_enu(100.0, 30.0), R_cam_from_enu(100.0, 30.0, 90.0)
    assert np.allclose(R[2], R0[2]) and np.allclose(R[0], R0[1]) and np.allclose(R[1], -R0[0])


def test_enu_to_ecef_is_the_papers_M() -> None:
    lat, lon = np.radians(34.27), np.radians(108.95)
    M = np.array(
        [
            [-np.sin(lon), -np.sin(lat) * np.cos(lon), np.cos(lat) * np.cos(lon)],
            [np.cos(lon), -np.sin(lat) * np.sin(lon), np.cos(lat) * np.sin(lon)],
            [0, np.cos(lat), np.sin(lat)],
        ]
    )
    assert np.allclose(R_ecef_from_enu(34.27, 108.95), M)


@pytest.mark.parametrize(
    ("L", "alpha", "beta"),
    [((0.79, 0.26, -0.55), -33.7, 72.0), ((0.10, 0.18, 0.98), 77.9, 28.9), ((0.54, 0.60, 0.59), 36.4, 41.9)],
)
def test_pitch_and_yaw_follow_eq_1_on_table_1(L: tuple[float, float, float], alpha: float, beta: float) -> None:
    pitch, yaw = pitch_yaw_deg(np.array(L))
    assert pitch == pytest.approx(alpha, abs=1.0) and yaw == pytest.approx(beta, abs=1.5)
