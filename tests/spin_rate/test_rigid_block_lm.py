"""The block-sparse Levenberg-Marquardt (``numerics.block_lm``) against scipy's MINPACK LM, its
Schur-complement step against the dense solve of the same damped normal equations, and the rigid
model's gauge against its Jacobian."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from scipy.optimize import least_squares

from tumblescan.numerics.block_lm import BlockNormal, block_lm
from tumblescan.spin_rate.rigid import Observations, fit_rigid, init_structure
from tumblescan.spin_rate.rigid_model import RigidModel
from tumblescan.spin_rate.rotation import unit_from_angles

from .test_robust_fit import synthetic_tracks

Fun = Callable[[np.ndarray], np.ndarray]


def _decay_problem(
    seed: int,
) -> tuple[Fun, Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], np.ndarray, np.ndarray, Fun]:
    """Curves ``y = a_i exp(-k t) + b_i cos(ω t)`` with shared (k, ω) and per-curve (a_i, b_i):
    residuals, the block Jacobian, the start, the row blocks and the dense Jacobian's callable."""
    rng = np.random.default_rng(seed)
    n_curves = 7
    n_rows = rng.integers(4, 12, n_curves)
    row_block = np.repeat(np.arange(n_curves), n_rows)
    t = rng.uniform(0, 4, len(row_block))
    k, w = 0.7, 1.9
    ab = rng.uniform(0.5, 2.0, (n_curves, 2))
    y = ab[row_block, 0] * np.exp(-k * t) + ab[row_block, 1] * np.cos(w * t) + rng.normal(0, 0.01, len(t))

    def fun(x: np.ndarray) -> np.ndarray:
        a, b = x[2:].reshape(-1, 2)[row_block].T
        return np.asarray(a * np.exp(-x[0] * t) + b * np.cos(x[1] * t) - y)

    def jac_blocks(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a, b = x[2:].reshape(-1, 2)[row_block].T
        J_global = np.column_stack([-t * a * np.exp(-x[0] * t), -t * b * np.sin(x[1] * t)])
        J_block = np.column_stack([np.exp(-x[0] * t), np.cos(x[1] * t)])
        return J_global, J_block

    def jac_dense(x: np.ndarray) -> np.ndarray:
        J_global, J_block = jac_blocks(x)
        J = np.zeros((len(t), 2 + 2 * n_curves))
        J[:, :2] = J_global
        for c in range(2):
            J[np.arange(len(t)), 2 + 2 * row_block + c] = J_block[:, c]
        return J

    x0 = np.concatenate([[0.5, 1.7], np.ones(2 * n_curves)])
    return fun, jac_blocks, x0, row_block, jac_dense


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_block_lm_reaches_minpacks_optimum(seed: int) -> None:
    fun, jac_blocks, x0, row_block, jac_dense = _decay_problem(seed)
    ref = least_squares(fun, x0, jac=jac_dense, method="lm", x_scale="jac", max_nfev=200)
    res = block_lm(fun, jac_blocks, x0, row_block, 2, max_nfev=200)
    assert ref.success and res.success
    np.testing.assert_allclose(res.x, ref.x, rtol=1e-7, atol=1e-9)
    assert res.cost == pytest.approx(ref.cost, rel=1e-10)
    assert res.nfev <= ref.nfev + 2


def test_block_lm_stops_at_max_nfev_like_minpack() -> None:
    fun, jac_blocks, x0, row_block, _ = _decay_problem(4)
    res = block_lm(fun, jac_blocks, x0, row_block, 2, max_nfev=3)
    assert res.nfev == 3 and res.status == 5 and not res.success


@pytest.mark.parametrize("par", [1e-6, 1e-2, 3.0])
def test_schur_step_equals_the_dense_damped_solve(par: float) -> None:
    fun, jac_blocks, _, row_block, jac_dense = _decay_problem(5)
    x = np.concatenate([[0.6, 1.8], np.random.default_rng(0).uniform(0.5, 2, 14)])
    J_global, J_block = jac_blocks(x)
    f = fun(x)
    normal = BlockNormal(J_global, J_block, f, row_block, 7)
    J = jac_dense(x)
    np.testing.assert_allclose(normal.column_norms, np.linalg.norm(J, axis=0), rtol=1e-12)
    np.testing.assert_allclose(normal.jtf, J.T @ f, rtol=1e-12, atol=1e-14)
    diag = normal.column_norms * np.random.default_rng(1).uniform(1.0, 2.0, J.shape[1])
    normal.scale(diag)
    normal.factor(par)
    z = np.asarray(np.random.default_rng(2).normal(size=J.shape[1]), dtype=float)
    Js = J / diag
    dense = np.linalg.solve(Js.T @ Js + par * np.eye(J.shape[1]), z)
    np.testing.assert_allclose(normal.solve(z), dense, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(normal.apply(z), Js @ z, rtol=1e-12, atol=1e-14)


def _rigid_problem(seed: int, drift: bool) -> tuple[RigidModel, np.ndarray, np.ndarray, Observations]:
    axis = unit_from_angles(np.radians(50.0), np.radians(30.0 + 70 * seed))
    obs, truth = synthetic_tracks(seed, axis, 3.0, drift_px_per_frame=0.5 if drift else 0.0)
    c0 = np.asarray(truth["c0"], dtype=float)
    omega = float(truth["rate"]) * 1.01  # type: ignore[arg-type]
    axis0 = unit_from_angles(np.radians(51.0), np.radians(31.0 + 70 * seed))  # a start in the optimum's basin
    t_ref = float(obs.t_s.min())
    p0, d0 = init_structure(obs, omega, axis0, c0, t_ref)
    model = RigidModel(obs.track, obs.t_s, obs.ends_px, obs.K, axis0, p0, d0, t_ref, drift)
    x0 = np.concatenate([[omega, 0.0, 0.0, c0[0], c0[1]], np.zeros(model.n_global - 5), np.zeros(4 * obs.n_tracks)])
    return model, x0, np.repeat(obs.track, 2), obs


@pytest.mark.parametrize("drift", [False, True])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_rigid_fit_reaches_minpacks_optimum(seed: int, drift: bool) -> None:
    """Both converge to the same motion and cost. The centre and lines may differ along the scale
    gauge (MINPACK follows it by round-off), so the residuals stand for the parameters. At the
    default tolerances both stop where a short track's line parameters are flat (the residuals up
    to 3e-4 px from the exact optimum on seed 1 with drift): costs within 1e-7; with tolerances
    of 1e-12 both reach the optimum: residuals within 1e-5 px (4.5e-6 on seed 1 with drift)."""
    model, x0, rows, _ = _rigid_problem(seed, drift)
    ref = least_squares(model.residuals, x0, jac=model.jacobian, method="lm", x_scale="jac", max_nfev=200)
    res = block_lm(model.residuals, model.jacobian_blocks, x0, rows, model.n_global, max_nfev=200, gauge=model.gauge)
    assert ref.success and res.success
    assert res.cost == pytest.approx(ref.cost, rel=1e-7)
    assert res.nfev <= ref.nfev
    tol = 1e-12
    ref = least_squares(
        model.residuals, x0, jac=model.jacobian, method="lm", x_scale="jac", ftol=tol, xtol=tol, gtol=tol, max_nfev=400
    )
    res = block_lm(
        model.residuals, model.jacobian_blocks, x0, rows, model.n_global, gauge=model.gauge,
        ftol=tol, xtol=tol, gtol=tol, max_nfev=400,
    )  # fmt: skip
    assert ref.success and res.success
    assert res.cost == pytest.approx(ref.cost, rel=1e-10)
    omega_ref, a_ref = model.unpack(ref.x)[:2]
    omega, a = model.unpack(res.x)[:2]
    assert omega == pytest.approx(omega_ref, rel=1e-8)
    assert np.linalg.norm(a - a_ref) < 1e-7
    np.testing.assert_allclose(model.residuals(res.x), model.residuals(ref.x), atol=1e-5)


@pytest.mark.parametrize("drift", [False, True])
def test_the_gauge_is_a_null_direction_of_the_jacobian(drift: bool) -> None:
    """``gauge`` with each line's point moved by ``-a - a_z p`` (re-expressed in its plane of
    points, sliding along the line) leaves the residuals unchanged to first order."""
    model, x0, _, _ = _rigid_problem(3, drift)
    x = x0.copy()
    x[1:3] = [0.05, -0.04]
    if drift:
        x[5:7] = [0.002, -0.001]
    x[model.n_global :] = np.random.default_rng(3).uniform(-0.05, 0.05, len(x) - model.n_global)
    _, a, _, _, p, d = model.unpack(x)
    n = np.zeros(len(x))
    n[: model.n_global] = model.gauge(x)[0]
    dp = -a - a[2] * p  # (T, 3)
    dp = dp - d * (np.sum(model.d0 * dp, axis=1) / np.sum(model.d0 * d, axis=1))[:, None]
    n[model.n_global :] = np.column_stack([np.zeros((len(p), 2)), np.einsum("tij,ti->tj", model.f, dp)]).ravel()
    J = model.jacobian(x)
    assert np.linalg.norm(J @ n) < 1e-9 * np.linalg.norm(J, axis=0).max() * np.linalg.norm(n)


def test_fit_rigid_keeps_the_centre_on_its_gauge() -> None:
    """A converged fit does not wander along the scale gauge: refitted from its own result, the
    centre stays put (MINPACK moved it by up to 10 of its units on benchmark sequences)."""
    model, x0, _, obs = _rigid_problem(1, False)
    fit = fit_rigid(obs, float(x0[0]), model.axis0, np.array([x0[3], x0[4], 1.0]), model.t_ref, passes=1)
    again = fit_rigid(obs, fit.omega_rad_s, fit.axis, fit.c0, model.t_ref, passes=1)
    assert np.linalg.norm(again.c0 - fit.c0) < 1e-4
    assert again.omega_rad_s == pytest.approx(fit.omega_rad_s, rel=1e-7)


def test_the_gauge_projected_solve_solves_the_equations_off_the_gauge() -> None:
    """With a gauge direction ``G`` of the globals, the solve's global part is orthogonal to ``G``,
    the block equations hold exactly and the global equations' residual lies along ``G``; a zero
    gauge is no gauge."""
    fun, jac_blocks, _, row_block, jac_dense = _decay_problem(6)
    x = np.concatenate([[0.6, 1.8], np.random.default_rng(0).uniform(0.5, 2, 14)])
    J_global, J_block = jac_blocks(x)
    normal = BlockNormal(J_global, J_block, fun(x), row_block, 7)
    normal.scale(normal.column_norms)
    Js = jac_dense(x) / normal.column_norms
    H = Js.T @ Js + 1e-3 * np.eye(Js.shape[1])
    z = np.asarray(np.random.default_rng(4).normal(size=Js.shape[1]), dtype=float)
    gauge = np.array([[1.0, -2.0]])
    normal.factor(1e-3, gauge)
    y = normal.solve(z)
    G = (gauge * normal.column_norms[:2]).ravel()
    assert abs(G @ y[:2]) < 1e-12 * np.linalg.norm(y)
    res = H @ y - z
    np.testing.assert_allclose(res[2:], 0.0, atol=1e-10)
    assert abs(res[0] * G[1] - res[1] * G[0]) < 1e-10 * np.linalg.norm(z)
    normal.factor(1e-3, np.zeros((1, 2)))
    np.testing.assert_allclose(normal.solve(z), np.linalg.solve(H, z), rtol=1e-9, atol=1e-12)
