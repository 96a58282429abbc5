"""Levenberg-Marquardt for least squares whose unknowns are a few global parameters and many
small blocks, each block touching only its own rows (bundle-adjustment structure).

The normal matrix ``[[U, W], [Wᵀ, V]]`` of such a problem has ``V`` block-diagonal, so each
damped step eliminates the blocks (Schur complement ``S = U - W V⁻¹ Wᵀ``), solves the small
global system and back-substitutes: per block ``b×b`` products (each block's eigenvectors taken
once per Jacobian serve every damping), stacked, instead of a dense QR of the whole Jacobian.

The iteration is Moré's (MINPACK ``lmder`` / ``lmpar``, as ``scipy.optimize.least_squares(
method="lm", x_scale="jac")`` runs it): variables scaled by the running maximum of the
Jacobian's column norms, a trust region ``Δ`` on the scaled step whose damping ``λ`` is found by
Moré's safeguarded Newton iteration on ``‖D p(λ)‖ = Δ``, the same ratio tests and ``Δ`` updates,
the same stopping tests (``ftol``, ``xtol``, ``gtol``) and ``max_nfev`` counting residual
evaluations. Where MINPACK works on the QR factors of ``J``, this works on the normal equations
(scaled to unit column norms), so the Gauss-Newton step is taken with a tiny damping (``rcond``)
that bounds it in nearly singular directions, and the global parts of known exact null directions
(a gauge: ``gauge``) are kept out of it, so that round-off does not move the solution along them
(MINPACK's QR does follow such a direction, by round-off, wherever it happens to lead).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray, IntArray

_EPS = float(np.finfo(float).eps)
_DWARF = float(np.finfo(float).tiny)


@dataclass(frozen=True)
class BlockLMResult:
    """``x`` the solution, ``fun`` its residuals, ``cost = ½‖fun‖²``; ``status`` as MINPACK's
    ``info`` (1-4 converged: ftol, xtol, both, gtol; 5 ``max_nfev`` reached)."""

    x: FloatArray
    fun: FloatArray
    cost: float
    nfev: int
    njev: int
    status: int

    @property
    def success(self) -> bool:
        return 1 <= self.status <= 4


def block_starts(row_block: IntArray) -> IntArray:
    """The index of each block's first row (``row_block`` non-decreasing)."""
    if not len(row_block):
        return np.zeros(0, int)
    return np.flatnonzero(np.concatenate([[True], row_block[1:] != row_block[:-1]]))


def block_moments(
    J_global: FloatArray, J_block: FloatArray, f: FloatArray, row_block: IntArray
) -> tuple[IntArray, FloatArray]:
    """Every present block's ``Zᵀ Z`` with ``Z = [J_global | J_block | f]`` over its rows (P, n, n),
    ``n = g + b + 1``, in one pass over the rows, and the blocks' first rows (``block_starts``):
    ``J_globalᵀ J_global``, ``J_globalᵀ J_block``, ``J_blockᵀ J_block`` and ``Jᵀ f`` per block."""
    starts = block_starts(row_block)
    Z = np.concatenate([J_global, J_block, f[:, None]], axis=1)
    n = Z.shape[1]
    blocks = np.add.reduceat(Z[:, :, None] * Z[:, None, :], starts, axis=0) if len(starts) else np.zeros((0, n, n))
    return starts, blocks


class BlockNormal:
    """The normal equations of one Jacobian, scaled, ready for damped solves.

    ``J_global`` (m, g) and ``J_block`` (m, b): row i's global columns, and its columns of block
    ``row_block[i]`` (non-decreasing); ``f`` (m,) residuals. ``scale(diag)`` divides the columns
    by ``diag`` (g + B·b,), so the solves work on the scaled step ``D p``."""

    def __init__(
        self, J_global: FloatArray, J_block: FloatArray, f: FloatArray, row_block: IntArray, n_blocks: int
    ) -> None:
        g, b = J_global.shape[1], J_block.shape[1]
        self.g, self.b, self.n_blocks = g, b, n_blocks
        self.J_global, self.J_block, self.row_block = J_global, J_block, row_block
        starts, blocks = block_moments(J_global, J_block, f, row_block)
        present = row_block[starts]
        self._U = blocks[:, :g, :g].sum(axis=0)
        self._W = np.zeros((n_blocks, g, b))
        self._V = np.zeros((n_blocks, b, b))
        grad_block = np.zeros((n_blocks, b))
        self._W[present] = blocks[:, :g, g : g + b]
        self._V[present] = blocks[:, g : g + b, g : g + b]
        grad_block[present] = blocks[:, g : g + b, -1]
        self.jtf = np.concatenate([blocks[:, :g, -1].sum(axis=0), grad_block.ravel()])
        """``Jᵀ f`` (g + B·b,), unscaled."""
        self.column_norms = np.sqrt(
            np.maximum(np.concatenate([np.diagonal(self._U), np.diagonal(self._V, axis1=1, axis2=2).ravel()]), 0.0)
        )
        self._par: float | None = None

    def scale(self, diag: FloatArray) -> None:
        """Divide the columns by ``diag`` (g + B·b,) for the solves that follow, and take each
        block's eigenvectors ``V_j = Q_j Λ_j Q_jᵀ``: every damping then costs one small product
        (``(V_j + λ I)⁻¹ = Q_j (Λ_j + λ)⁻¹ Q_jᵀ``), and the solves work in the coordinates
        ``(y_global, Q_jᵀ y_j)`` ("hat" coordinates, the same norms)."""
        g, b, B = self.g, self.b, self.n_blocks
        dg, db = diag[:g], diag[g:].reshape(B, b)
        self.diag = diag
        self.U = self._U / np.outer(dg, dg)
        self.W = self._W / (dg[None, :, None] * db[:, None, :])
        self.V = self._V / (db[:, :, None] * db[:, None, :])
        lam, Q = np.linalg.eigh(self.V)
        self._lam = np.maximum(lam, 0.0).ravel()  # (B·b,): V is positive semi-definite
        self._Q = Q
        self._W_hat = (self.W @ Q).transpose(1, 0, 2).reshape(g, B * b)  # (g, B·b): W_j Q_j side by side
        self.grad = self.jtf / diag
        self.grad_hat = self.to_hat(self.grad)
        self._par = None
        self.gauss_newton: tuple[FloatArray, float] | None = None

    def to_hat(self, y: FloatArray) -> FloatArray:
        """``(y_global, Q_jᵀ y_j)`` of a scaled vector ``y``."""
        yb = y[self.g :].reshape(self.n_blocks, self.b, 1)
        return np.concatenate([y[: self.g], (self._Q.transpose(0, 2, 1) @ yb).ravel()])

    def from_hat(self, y_hat: FloatArray) -> FloatArray:
        """The scaled vector of hat coordinates ``y_hat``."""
        yb = y_hat[self.g :].reshape(self.n_blocks, self.b, 1)
        return np.concatenate([y_hat[: self.g], (self._Q @ yb).ravel()])

    def factor(self, par: float, gauge: FloatArray | None = None) -> None:
        """Prepare solves of ``(J̃ᵀJ̃ + par·I) y = z`` (``J̃`` the scaled Jacobian, ``par > 0``).

        ``gauge`` (k, g): the global parts of exact null directions of ``J`` (unscaled), kept out
        of the global solution (the Schur complement ``S`` has them as exact null vectors, but
        computes them as round-off, up to ~1e-9 of the scaled ``J̃ᵀJ̃``, near the genuine small
        eigenvalues of weakly determined fits): for the nearly undamped Gauss-Newton step."""
        g = self.g
        inv_lam = 1.0 / (self._lam + par)
        S = self.U - (self._W_hat * inv_lam) @ self._W_hat.T + par * np.eye(g)
        G = np.zeros((g, 0)) if gauge is None else (gauge * self.diag[:g]).T  # (g, k), scaled
        if G.shape[1] and np.linalg.norm(G) > 0:  # made orthonormal
            G = G / np.linalg.norm(G) if G.shape[1] == 1 else np.linalg.qr(G)[0]
            P = np.eye(g) - G @ G.T
            S_inv = P @ np.linalg.inv(P @ S @ P + G @ G.T) @ P  # the inverse on the complement of G
        else:
            S_inv = np.linalg.inv(S)
        self._inv_lam, self._S_inv, self._par = inv_lam, S_inv, par

    def solve_hat(self, z_hat: FloatArray) -> FloatArray:
        """``(J̃ᵀJ̃ + par·I)⁻¹ z`` for the last ``factor``, ``z`` and the result in hat coordinates:
        the Schur complement's solve, then the blocks' back-substitution."""
        assert self._par is not None
        zg, zb = z_hat[: self.g], z_hat[self.g :]
        yg = self._S_inv @ (zg - self._W_hat @ (self._inv_lam * zb))
        return np.concatenate([yg, self._inv_lam * (zb - self._W_hat.T @ yg)])

    def solve(self, z: FloatArray) -> FloatArray:
        """``y = (J̃ᵀJ̃ + par·I)⁻¹ z`` (g + B·b,) for the last ``factor`` (scaled coordinates)."""
        return self.from_hat(self.solve_hat(self.to_hat(z)))

    def apply(self, y: FloatArray) -> FloatArray:
        """``J̃ y`` (m,) for a scaled vector ``y`` (``J`` times the unscaled ``y / diag``)."""
        p = y / self.diag
        pb = p[self.g :].reshape(self.n_blocks, self.b)
        return np.asarray(
            self.J_global @ p[: self.g] + np.einsum("ik,ik->i", self.J_block, pb[self.row_block]), dtype=float
        )


def _lm_parameter(
    normal: BlockNormal, delta: float, par: float, rcond: float, gauge: FloatArray | None
) -> tuple[float, FloatArray]:
    """Moré's ``lmpar``: the damping ``par`` and scaled step ``D p`` with ``‖D p‖ ≈ Δ`` (within 10 %),
    or the Gauss-Newton step (``par = 0``) when it is shorter than ``1.1 Δ``. The Gauss-Newton step
    is damped by ``rcond`` (the scaled columns have norms ≤ 1), which bounds it in (nearly) singular
    directions; its Newton bound ``parl`` is then a bound for ``par - rcond``, still a lower bound."""
    minus_grad = -normal.grad_hat  # all in hat coordinates (the same norms), the step converted at the end
    if normal.gauss_newton is None:  # the same for every inner iteration of one Jacobian
        normal.factor(rcond, gauge)
        step0 = normal.solve_hat(minus_grad)
        norm0 = float(np.linalg.norm(step0))
        normal.gauss_newton = (step0, float(step0 @ normal.solve_hat(step0)) / norm0**2 if norm0 > 0 else 0.0)
    step, qhq = normal.gauss_newton
    dxnorm = float(np.linalg.norm(step))
    fp = dxnorm - delta
    if fp <= 0.1 * delta:
        return 0.0, normal.from_hat(step)
    parl = (fp / delta) / qhq if qhq > 0 else 0.0
    gnorm = float(np.linalg.norm(minus_grad))
    paru = gnorm / delta
    if paru == 0:
        paru = _DWARF / min(delta, 0.1)
    par = min(max(par, parl), paru)
    if par == 0:
        par = gnorm / dxnorm
    for it in range(1, 11):
        if par == 0:
            par = max(_DWARF, 0.001 * paru)
        normal.factor(par)
        step = normal.solve_hat(minus_grad)
        dxnorm = float(np.linalg.norm(step))
        previous, fp = fp, dxnorm - delta
        if abs(fp) <= 0.1 * delta or (parl == 0 and fp <= previous and previous < 0) or it == 10:
            break
        parc = (fp / delta) / (float(step @ normal.solve_hat(step)) / dxnorm**2)
        if fp > 0:
            parl = max(parl, par)
        if fp < 0:
            paru = min(paru, par)
        par = max(parl, par + parc)
    return par, normal.from_hat(step)


def block_lm(
    fun: Callable[[FloatArray], FloatArray],
    jac: Callable[[FloatArray], tuple[FloatArray, FloatArray]],
    x0: FloatArray,
    row_block: IntArray,
    n_global: int,
    *,
    max_nfev: int,
    ftol: float = 1e-8,
    xtol: float = 1e-8,
    gtol: float = 1e-8,
    factor: float = 100.0,
    rcond: float = 1e-12,
    gauge: Callable[[FloatArray], FloatArray] | None = None,
) -> BlockLMResult:
    """Minimise ``½‖fun(x)‖²`` by Levenberg-Marquardt from ``x0`` (see the module docstring).

    Parameters
    ----------
    fun : x -> residuals (m,).
    jac : x -> ``(J_global (m, n_global), J_block (m, b))``: each row's derivatives by the global
        parameters ``x[:n_global]`` and by its own block's ``x[n_global + b·j : n_global + b·(j+1)]``,
        ``j = row_block[row]``.
    x0 : (n_global + B·b,) start; row_block : (m,) non-decreasing block of each row.
    max_nfev : at most this many residual evaluations (the start's included), as MINPACK's maxfev.
    ftol, xtol, gtol, factor : MINPACK's tolerances and initial step bound factor.
    rcond : the damping of the Gauss-Newton step (of the scaled normal matrix, diagonal ≤ 1).
    gauge : x -> (k, n_global) the global parts of the model's exact null directions at x (a gauge
        freedom), left out of the undamped step (see ``BlockNormal.factor``); None: none known.
    """
    x = np.array(x0, dtype=float)
    f = np.asarray(fun(x), dtype=float)
    nfev, njev = 1, 0
    fnorm = float(np.linalg.norm(f))
    par, delta, xnorm = 0.0, 0.0, 0.0
    diag = np.zeros(0)
    first = True
    status = 0
    while status == 0:
        J_global, J_block = jac(x)
        njev += 1
        gauge_x = gauge(x) if gauge is not None else None
        normal = BlockNormal(J_global, J_block, f, row_block, (len(x) - n_global) // J_block.shape[1])
        colnorm = normal.column_norms
        if first:
            diag = np.where(colnorm == 0, 1.0, colnorm)
            xnorm = float(np.linalg.norm(diag * x))
            delta = factor * xnorm if xnorm != 0 else factor
        gnorm = 0.0
        nz = colnorm != 0
        if fnorm != 0 and nz.any():
            gnorm = float(np.max(np.abs(normal.jtf[nz] / colnorm[nz]))) / fnorm
        if gnorm <= gtol:
            status = 4
            break
        diag = np.maximum(diag, colnorm)
        normal.scale(diag)
        while True:
            par, scaled_step = _lm_parameter(normal, delta, par, rcond, gauge_x)
            step = scaled_step / diag
            x_new = x + step
            pnorm = float(np.linalg.norm(scaled_step))
            if first:
                delta = min(delta, pnorm)
            f_new = np.asarray(fun(x_new), dtype=float)
            nfev += 1
            fnorm1 = float(np.linalg.norm(f_new))
            actred = 1.0 - (fnorm1 / fnorm) ** 2 if 0.1 * fnorm1 < fnorm else -1.0
            temp1 = float(np.linalg.norm(normal.apply(scaled_step))) / fnorm
            temp2 = np.sqrt(par) * pnorm / fnorm
            prered = temp1**2 + temp2**2 / 0.5
            dirder = -(temp1**2 + temp2**2)
            ratio = actred / prered if prered != 0 else 0.0
            if ratio <= 0.25:
                temp = 0.5 if actred >= 0 else 0.5 * dirder / (dirder + 0.5 * actred)
                if 0.1 * fnorm1 >= fnorm or temp < 0.1:
                    temp = 0.1
                delta = temp * min(delta, pnorm / 0.1)
                par = par / temp
            elif par == 0 or ratio >= 0.75:
                delta = pnorm / 0.5
                par = 0.5 * par
            if ratio >= 1e-4:
                x, f, fnorm = x_new, f_new, fnorm1
                xnorm = float(np.linalg.norm(diag * x))
                first = False
            ftol_met = abs(actred) <= ftol and prered <= ftol and 0.5 * ratio <= 1
            xtol_met = delta <= xtol * xnorm
            if ftol_met or xtol_met:
                status = 3 if ftol_met and xtol_met else (1 if ftol_met else 2)
            elif nfev >= max_nfev:
                status = 5
            elif abs(actred) <= _EPS and prered <= _EPS and 0.5 * ratio <= 1:
                status = 6
            elif delta <= _EPS * xnorm:
                status = 7
            elif gnorm <= _EPS:
                status = 8
            if status != 0 or ratio >= 1e-4:
                break
    return BlockLMResult(x=x, fun=f, cost=0.5 * fnorm**2, nfev=nfev, njev=njev, status=status)
