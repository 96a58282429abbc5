"""The rigid fit's σ (``rigid.covariances``), computed on the global parameters with each track's
lines eliminated, against the same three estimates from the dense Jacobian: the Gauss-Newton and
cluster-robust covariances from the pseudo-inverse of the full normal matrix, and the track
jackknife with each track deleted from the full normal equations."""

from __future__ import annotations

import numpy as np
import pytest

from tumblescan.numerics.block_lm import block_lm
from tumblescan.spin_rate.rigid import covariances, fit_rigid, init_structure
from tumblescan.spin_rate.rigid_model import RigidModel

from .test_rigid_block_lm import _rigid_problem


def _dense_covariances(model: RigidModel, x: np.ndarray, r: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, ...]:
    J = model.jacobian(x) * np.sqrt(w)[:, None]
    rw = np.sqrt(w) * r
    rows = np.repeat(model.track, 2)
    G, n_par = int(model.track.max()) + 1, J.shape[1]
    # The full normal matrix spans 14 orders of magnitude (ω in rad/s beside px-scaled line
    # parameters) and is singular along the scale gauge only, 1e-19 of its largest eigenvalue.
    H_inv = np.linalg.pinv(J.T @ J, rcond=1e-16, hermitian=True)
    cov = H_inv * float(np.sum(w * r**2) / (np.sum(w) - n_par))
    g = np.array([J[rows == j].T @ rw[rows == j] for j in range(G)])
    cov_cluster = H_inv @ (g.T @ g) @ H_inv * G / (G - 1)
    # Without track j: drop its rows (its own line columns become empty) and take one step.
    delta = []
    for j in range(G):
        keep = rows != j
        own = model.n_global + 4 * j + np.arange(4)
        cols = np.setdiff1d(np.arange(n_par), own)
        Jk = J[np.ix_(keep, cols)]
        delta.append((np.linalg.pinv(Jk.T @ Jk, rcond=1e-16, hermitian=True) @ (Jk.T @ rw[keep]))[0])
    d = np.array(delta)
    return cov, cov_cluster, np.sqrt((G - 1) / G * np.sum((d - d.mean()) ** 2))


def _weighted(blocks: tuple[np.ndarray, np.ndarray], sw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return sw[:, None] * blocks[0], sw[:, None] * blocks[1]


@pytest.mark.parametrize("drift", [False, True])
@pytest.mark.parametrize("seed", [1, 2])
def test_schur_covariances_equal_the_dense_ones(seed: int, drift: bool) -> None:
    """At a weighted least-squares optimum (the jackknife's one-step deletions assume one), for the
    rate and the axis: the parameters that do not move along the gauge."""
    model0, x0, _, obs = _rigid_problem(seed, drift)
    fit = fit_rigid(obs, float(x0[0]), model0.axis0, np.array([x0[3], x0[4], 1.0]), model0.t_ref, drift=drift)
    assert fit.sigma_omega_rad_s > 0 and np.isfinite(fit.sigma_omega_rad_s)
    p, d = init_structure(obs, fit.omega_rad_s, fit.axis, fit.c0, model0.t_ref)
    model = RigidModel(obs.track, obs.t_s, obs.ends_px, obs.K, fit.axis, p, d, model0.t_ref, drift)
    x = np.concatenate(
        [[fit.omega_rad_s, 0, 0, fit.c0[0], fit.c0[1]], fit.velocity[:2] if drift else [], np.zeros(4 * obs.n_tracks)]
    )
    w = fit.weights
    sw = np.sqrt(w)
    x = block_lm(
        lambda z: sw * model.residuals(z),
        lambda z: _weighted(model.jacobian_blocks(z), sw),
        x, np.repeat(obs.track, 2), model.n_global, max_nfev=300, ftol=1e-14, xtol=1e-14, gtol=1e-14,
        gauge=model.gauge,
    ).x  # fmt: skip
    r = model.residuals(x)
    ours = covariances(model, x, r, w)
    dense = _dense_covariances(model, x, r, w)
    for cov, cov_ref in zip(ours[:2], dense[:2], strict=True):
        np.testing.assert_allclose(cov[:3, :3], cov_ref[:3, :3], rtol=1e-5, atol=1e-6 * abs(cov_ref[0, 0]))
    assert ours[2] == pytest.approx(dense[2], rel=1e-5)
