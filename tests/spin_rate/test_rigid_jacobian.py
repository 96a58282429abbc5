"""The rigid model's analytic Jacobian against central differences, with and without drift, away
from x = 0 (axis and line parameters off their starting values)."""

from __future__ import annotations

import numpy as np
import pytest

from tumblescan.spin_rate.rigid import Observations, init_structure
from tumblescan.spin_rate.rigid_model import RigidModel
from tumblescan.spin_rate.rotation import unit_from_angles

from .test_robust_fit import synthetic_tracks


def central_differences(model: RigidModel, x: np.ndarray, h_rel: float = 1e-4) -> np.ndarray:
    """Central-difference Jacobian (2·O, P) of ``model.residuals``, one parameter at a time. The
    step is larger than the fit's old 1e-6: a residual is a difference of terms of hundreds of px,
    so at 1e-8 steps round-off alone is 3e-6 of a small column (truncation at 1e-4 is below 1e-7)."""
    J = np.zeros((2 * len(model.track), len(x)))
    for k in range(len(x)):
        h = h_rel * max(abs(x[k]), 1e-2)
        dx = np.zeros(len(x))
        dx[k] = h
        J[:, k] = (model.residuals(x + dx) - model.residuals(x - dx)) / (2 * h)
    return J


@pytest.mark.parametrize("drift", [False, True])
@pytest.mark.parametrize("seed", [1, 2])
def test_analytic_jacobian_matches_central_differences(seed: int, drift: bool) -> None:
    axis = unit_from_angles(np.radians(50.0), np.radians(30.0 + 70 * seed))
    obs, truth = synthetic_tracks(seed, axis, 3.0)
    c0 = np.asarray(truth["c0"], dtype=float)
    omega, t_ref = np.radians(3.0), float(obs.t_s.min())
    p0, d0 = init_structure(obs, omega, axis, c0, t_ref)
    model = RigidModel(obs.track, obs.t_s, obs.ends_px, obs.K, axis, p0, d0, t_ref, drift)
    rng = np.random.default_rng(seed)
    n_global = model.n_global
    x = np.concatenate([[omega, 0.0, 0.0, c0[0], c0[1]], np.zeros(n_global - 5), np.zeros(4 * obs.n_tracks)])
    x[1:3] = rng.uniform(-0.2, 0.2, 2)  # the axis 10-15° off axis0
    if drift:
        x[5:7] = rng.uniform(-0.01, 0.01, 2)
    x[n_global:] = rng.uniform(-0.1, 0.1, 4 * obs.n_tracks) * np.tile([1.0, 1.0, 0.02, 0.02], obs.n_tracks)
    J = model.jacobian(x)
    J_fd = central_differences(model, x)
    assert J.shape == J_fd.shape == (2 * len(obs.track), n_global + 4 * obs.n_tracks)
    scale = np.abs(J_fd).max(axis=0)
    assert np.all(scale > 0)
    np.testing.assert_array_less(np.abs(J - J_fd).max(axis=0) / scale, 1e-6)
    # A line's parameters touch only its own observations' rows.
    rows_track = np.repeat(obs.track, 2)
    for t in range(obs.n_tracks):
        np.testing.assert_array_equal(J[rows_track != t, n_global + 4 * t : n_global + 4 * t + 4], 0.0)


def test_jacobian_rows_follow_sorted_observations() -> None:
    """``Observations.build`` sorts by track; the Jacobian's rows follow ``residuals``' order."""
    obs, truth = synthetic_tracks(3, unit_from_angles(0.3, 1.0), 4.0)
    order = np.random.default_rng(0).permutation(len(obs.track))
    shuffled = Observations.build(obs.track[order], obs.t_s[order], obs.ends_px[order], obs.K)
    axis = unit_from_angles(0.3, 1.0)
    c0 = np.asarray(truth["c0"], dtype=float)
    p0, d0 = init_structure(shuffled, 0.07, axis, c0, 0.0)
    model = RigidModel(shuffled.track, shuffled.t_s, shuffled.ends_px, shuffled.K, axis, p0, d0, 0.0, False)
    x = np.concatenate([[0.07, 0.05, -0.03, c0[0], c0[1]], np.full(4 * shuffled.n_tracks, 0.01)])
    J_fd = central_differences(model, x)
    np.testing.assert_allclose(model.jacobian(x), J_fd, atol=1e-6 * np.abs(J_fd).max())
