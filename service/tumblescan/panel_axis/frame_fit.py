"""The panel frame: the axis and the directions orthogonal to it.

A wing is a rectangle: its long edges run along the axis ``d`` and its end edges and sub-panel gaps
along the short direction ``s ⟂ d``; the bus edges across the axis are ⟂ ``d`` as well. With
back-projected unit plane normals ``n_i`` (camera frame), their σ_i and Huber weights ``w_i``:

- ``fit_panel_frame``: the axis jointly with families known to be orthogonal to it. ``d`` moves in
  its tangent plane (2 parameters ``p``) and each family ``j`` is ``d_j = cos ψ_j·e1(d) + sin ψ_j·e2(d)``,
  orthogonal to ``d`` by construction:
  ``min Σ_i∈axis w_i (n_i·d)²/σ_i(d)² + Σ_j Σ_k∈j w_k (n_k·d_j)²/σ_k(d_j)²``
  (``scipy.optimize.least_squares``, Levenberg-Marquardt); edges over 5σ after a first solve are
  dropped and it is solved again (the joint fit pins the axis's depth tilt well enough to tell a
  biased edge, one beside the bus, from a good one). The axis covariance is the ``p`` block of
  ``(JᵀJ)⁻¹·max(1, χ²/dof)``.
- ``fit_about_axis``: one family's direction ⟂ a given axis (ψ only), with its covariance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray
from .axis import REJECT_K, DirectionFit, PlaneObs, PlaneStack


@dataclass(frozen=True)
class FrameFit:
    """``axis``: the axis fit (direction, tangent basis (2, 3), covariance (2, 2) rad²);
    ``directions``: the unit (3,) direction of each other family, ⟂ the axis."""

    axis: DirectionFit
    directions: list[FloatArray]


def fit_panel_frame(
    axis: DirectionFit, axis_planes: list[PlaneObs], others: list[tuple[DirectionFit, list[PlaneObs]]]
) -> FrameFit:
    """The joint fit of the module docstring. ``axis`` and each ``others[j][0]`` are the separate
    fits (start values and Huber weights); ``axis_planes`` and ``others[j][1]`` their planes."""
    from scipy.optimize import least_squares

    d0 = axis.direction
    basis0 = axis.basis

    def frame(p: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        d = d0 + p[0] * basis0[0] + p[1] * basis0[1]
        d = d / np.linalg.norm(d)
        e1 = basis0[0] - (basis0[0] @ d) * d
        e1 /= np.linalg.norm(e1)
        return d, e1, np.cross(d, e1)

    def other(p: FloatArray, j: int) -> FloatArray:
        _, e1, e2 = frame(p)
        return np.asarray(np.cos(p[2 + j]) * e1 + np.sin(p[2 + j]) * e2, dtype=float)

    groups = [(PlaneStack(axis_planes), np.sqrt(axis.weights))]
    groups += [(PlaneStack(pl), np.sqrt(f.weights)) for f, pl in others]
    sizes = np.cumsum([0] + [len(st.N) for st, _ in groups])

    def residuals(p: FloatArray) -> FloatArray:
        out = []
        for j, (st, sw) in enumerate(groups):
            dj = frame(p)[0] if j == 0 else other(p, j - 1)
            out.append(sw * (st.N @ dj) / np.sqrt(st.sigma2(dj)))
        return np.concatenate(out)

    _, e1, e2 = frame(np.zeros(2))
    psi0 = [float(np.arctan2(f.direction @ e2, f.direction @ e1)) for f, _ in others]
    sol = least_squares(residuals, np.concatenate([[0.0, 0.0], psi0]), method="lm", x_scale="jac")
    big = np.abs(sol.fun) > REJECT_K
    if big.any() and np.count_nonzero(~big[: sizes[1]]) >= 3:
        for j, (_, sw) in enumerate(groups):
            sw[big[sizes[j] : sizes[j + 1]]] = 0.0
        sol = least_squares(residuals, sol.x, method="lm", x_scale="jac")
    x = sol.x
    d, _, _ = frame(x)
    r = sol.fun
    used = int(np.count_nonzero(np.concatenate([sw for _, sw in groups]) > 0))
    dof = max(used - len(x), 1)
    chi2 = float(r @ r)
    cov_all = np.linalg.pinv(sol.jac.T @ sol.jac) * max(1.0, chi2 / dof)
    # p moves d along basis0 to first order; express its block in a basis ⟂ d.
    basis = np.array([b - (b @ d) * d for b in basis0])
    norms = np.linalg.norm(basis, axis=1)
    basis = basis / norms[:, None]
    cov_axis = cov_all[:2, :2] * np.outer(norms, norms)
    res_axis = residuals(x)[: len(axis_planes)]
    axis_fit = DirectionFit(d, basis, cov_axis, chi2, dof, res_axis, groups[0][1] ** 2)
    return FrameFit(axis_fit, [other(x, j) for j in range(len(others))])


def fit_about_axis(axis: DirectionFit, fit: DirectionFit, planes: list[PlaneObs]) -> tuple[FloatArray, FloatArray]:
    """A family's direction constrained ⟂ a given axis ``d``: ``s(ψ) = cos ψ·e1(d) + sin ψ·e2(d)``,
    ``ψ = argmin Σ_k w_k (n_k·s)²/σ_k(s)²`` (Huber weights ``w_k`` of the family's separate ``fit``,
    which also gives the start). Returns the unit direction (3,) and its (3, 3) covariance:
    ``var ψ`` along ``d × s`` (Gauss-Newton curvature times ``max(1, χ²/dof)``) plus the axis's
    covariance carried through ``∂s/∂d`` (the fit redone about an axis moved along each tangent
    direction: it tips ``s`` with ``d`` and shifts ψ to fit the planes again)."""
    from scipy.optimize import least_squares

    st = PlaneStack(planes)
    sw = np.sqrt(fit.weights)
    used = int(np.count_nonzero(sw > 0))
    helper = axis.basis[0]

    def solve(d: FloatArray, psi0: float) -> tuple[FloatArray, float, float, FloatArray]:
        e1 = helper - (helper @ d) * d
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(d, e1)

        def residuals(p: FloatArray) -> FloatArray:
            s = np.cos(p[0]) * e1 + np.sin(p[0]) * e2
            return np.asarray(sw * (st.N @ s) / np.sqrt(st.sigma2(s)), dtype=float)

        sol = least_squares(residuals, np.array([psi0]), method="lm", x_scale="jac")
        psi = float(sol.x[0])
        scale = max(1.0, float(sol.fun @ sol.fun) / (used - 1)) if used > 1 else 1.0
        var_psi = scale / max(float((sol.jac.T @ sol.jac)[0, 0]), 1e-30)
        return np.cos(psi) * e1 + np.sin(psi) * e2, psi, var_psi, e1

    d = axis.direction
    e1 = helper - (helper @ d) * d
    e1 /= np.linalg.norm(e1)
    psi0 = float(np.arctan2(fit.direction @ np.cross(d, e1), fit.direction @ e1))
    s, psi, var_psi, _ = solve(d, psi0)
    h = 1e-6
    G = np.column_stack(
        [
            (solve(_unit(d + h * b), psi)[0] - solve(_unit(d - h * b), psi)[0]) / (2 * h)
            for b in axis.basis  # (3, 2): ∂s/∂(tangent of d)
        ]
    )
    t = np.cross(d, s)
    cov = var_psi * np.outer(t, t) + G @ axis.cov_tangent_rad2 @ G.T
    return s, cov


def _unit(v: FloatArray) -> FloatArray:
    return np.asarray(v / np.linalg.norm(v), dtype=float)
