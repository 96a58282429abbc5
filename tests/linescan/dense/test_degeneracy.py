"""The "no precession" test of the dense model choice, on 9-vectors with known covariances."""

from __future__ import annotations

import numpy as np

from tumblescan.geometry.rotations import angles_from_axis
from tumblescan.linescan.dense.degeneracy import precession_p_value


def _motion(spin_axis: np.ndarray, precession_axis: np.ndarray, w_p_deg_s: float) -> np.ndarray:
    x = np.zeros(9)
    x[0:2] = angles_from_axis(spin_axis)
    x[2] = np.radians(20.0)
    x[3:5] = angles_from_axis(precession_axis)
    x[5] = np.radians(w_p_deg_s)
    x[6:9] = (0.0, 0.0, 50.0)
    return x


def _cov(axis_sigma_deg: float, w_p_sigma_deg_s: float) -> np.ndarray:
    sd = np.full(9, 1e-3)
    sd[[0, 1, 3, 4]] = np.radians(axis_sigma_deg)
    sd[5] = np.radians(w_p_sigma_deg_s)
    return np.diag(sd**2)


def _tilted(axis: np.ndarray, angle_deg: float) -> np.ndarray:
    side = np.cross(axis, [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    a = np.radians(angle_deg)
    return np.cos(a) * axis + np.sin(a) * side


def test_a_precession_about_the_spin_axis_itself_is_not_significant() -> None:
    # The case a pure spin's fit ran into under load: a precession rate at 5 of its sigmas, but
    # about an axis 3.7 deg from the spin axis at 2.2 deg of sigma. The rate alone (Wald z = 5,
    # p = 6e-7) would keep the precession; across the spin axis it is 1.7 sigma.
    l_s = np.array([0.3, 0.8, 0.5]) / np.linalg.norm([0.3, 0.8, 0.5])
    x = _motion(l_s, _tilted(l_s, 3.7), w_p_deg_s=10.0)
    assert precession_p_value(x, _cov(axis_sigma_deg=2.2 / np.sqrt(2), w_p_sigma_deg_s=2.0)) > 1e-3


def test_a_precession_well_apart_from_the_spin_axis_is_significant() -> None:
    l_s = np.array([0.3, 0.8, 0.5]) / np.linalg.norm([0.3, 0.8, 0.5])
    x = _motion(l_s, _tilted(l_s, 30.0), w_p_deg_s=10.0)
    assert precession_p_value(x, _cov(axis_sigma_deg=0.5, w_p_sigma_deg_s=0.5)) < 1e-6


def test_a_slow_precession_within_its_sigma_is_not_significant() -> None:
    l_s = np.array([0.0, 0.0, 1.0])
    x = _motion(l_s, _tilted(l_s, 40.0), w_p_deg_s=0.5)
    assert precession_p_value(x, _cov(axis_sigma_deg=0.5, w_p_sigma_deg_s=0.5)) > 0.1
