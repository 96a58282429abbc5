"""The rigid model's parameters, residuals and analytic Jacobian (used by ``rigid.fit_rigid``).

Parameters ``x``: ``ω`` (rad/s), two axis tangents, ``c0_x, c0_y`` (units of the range), with
drift ``v_x, v_y`` (range/s), then 4 per track (2 direction tangents, 2 point offsets). For an
observation at ``dt = t_s - t_ref`` of track t: ``R = Rot(a, ω dt)``, ``X = c0 + v dt + R p_t``,
``D = R d_t``, ``u = K X``, ``w = K D``, ``l = u × w``, ``s = ‖(l₁, l₂)‖``, and the residual of
end point k is ``r_k = e_kᵀ l / s`` (px), ``e_k = (x, y, 1)``.
"""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray
from ..geometry.rotations import cross3, tangent_basis
from .rotation import rot


class RigidModel:
    """Parameter packing, residuals and Jacobian of the rigid model (see the module docstring)."""

    def __init__(
        self, track: np.ndarray, t_s: FloatArray, ends_px: FloatArray, K: FloatArray, axis0: FloatArray,
        p0: FloatArray, d0: FloatArray, t_ref: float, drift: bool,
    ) -> None:  # fmt: skip
        """track : (O,) track of each observation, sorted; t_s : (O,) time (s); ends_px : (O, 2, 2)
        end points (ideal px); K : (3, 3) camera matrix; axis0 : (3,) unit axis at x = 0;
        p0, d0 : (T, 3) each line's point and unit direction at x = 0; t_ref : reference time (s)."""
        self.track, self.K, self.t_ref, self.drift = track, K, t_ref, drift
        self.axis0 = axis0
        self.e_axis = tangent_basis(axis0)
        self.p0, self.d0 = p0, d0
        self.f = np.array([np.column_stack(tangent_basis(d)) for d in d0])  # (T, 3, 2)
        self.n_global = 5 + (2 if drift else 0)
        # One rotation per frame, not per observation: every line of a frame shares its time.
        self.dt = t_s - t_ref
        self.dt_frame, self.frame_of = np.unique(self.dt, return_inverse=True)
        self.e_h = np.concatenate([ends_px, np.ones((*ends_px.shape[:2], 1))], axis=2)  # (O, 2, 3)
        n_obs = len(track)
        # Where each observation's 2 rows put their 4 line derivatives in the dense Jacobian.
        self._rows = np.repeat(np.arange(2 * n_obs).reshape(n_obs, 2)[:, :, None], 4, axis=2)
        self._cols = np.broadcast_to((self.n_global + 4 * track)[:, None, None] + np.arange(4), (n_obs, 2, 4))

    def unpack(self, x: FloatArray) -> tuple[float, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        """``(ω, a, c0, v, p, d)`` from the parameter vector ``x``."""
        omega = float(x[0])
        a = self.axis0 + x[1] * self.e_axis[0] + x[2] * self.e_axis[1]
        a = a / np.linalg.norm(a)
        c0 = np.array([x[3], x[4], 1.0])
        v = np.array([x[5], x[6], 0.0]) if self.drift else np.zeros(3)
        L = x[self.n_global :].reshape(-1, 4)
        d = self.d0 + np.einsum("tij,tj->ti", self.f, L[:, :2])
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        p = self.p0 + np.einsum("tij,tj->ti", self.f, L[:, 2:])
        return omega, a, c0, v, p, d

    def _lines(
        self, omega: float, a: FloatArray, c0: FloatArray, v: FloatArray, p: FloatArray, d: FloatArray
    ) -> tuple[FloatArray, ...]:
        """Per observation: R (O, 3, 3), R p and R d (O, 3), u = K X, w = K D, l = u × w (O, 3)."""
        R = rot(a, omega * self.dt_frame)[self.frame_of]
        Rp = np.einsum("oij,oj->oi", R, p[self.track])
        Rd = np.einsum("oij,oj->oi", R, d[self.track])
        u = (c0 + v * self.dt[:, None] + Rp) @ self.K.T
        w = Rd @ self.K.T
        return R, Rp, Rd, u, w, cross3(u, w)

    def residuals(self, x: FloatArray) -> FloatArray:
        """The signed end-point distances (2·O,) px, observation-major."""
        *_, line = self._lines(*self.unpack(x))
        line = line / np.sqrt(line[:, 0] * line[:, 0] + line[:, 1] * line[:, 1])[:, None]
        return np.asarray(np.einsum("oki,oi->ok", self.e_h, line).ravel(), dtype=float)

    def jacobian(self, x: FloatArray) -> FloatArray:
        """The analytic Jacobian (2·O, P) of ``residuals``: globals first, then 4 columns per track.

        ``dr_k = g_k·dl`` with ``g_k = (e_k - r_k (l₁, l₂, 0)/s) / s``, and ``dl = (K dX) × w + u × (K dD)``,
        so ``dr_k = α_k·dX + β_k·dD`` with ``α_k = Kᵀ (w × g_k)``, ``β_k = Kᵀ (g_k × u)``. A rotation
        change ``dR = [δ]× R`` gives ``dX = δ × R p``, ``dD = δ × R d``: for ω, ``δ = dt a``; for the
        axis (``da`` tangent to the unit ``a``, ``φ = ω dt``) the SO(3) left Jacobian gives
        ``δ = sin φ da + (1 - cos φ) a × da``."""
        omega, a, c0, v, p, d = self.unpack(x)
        R, Rp, Rd, u, w, line = self._lines(omega, a, c0, v, p, d)
        n_obs = len(self.track)
        s = np.sqrt(line[:, 0] ** 2 + line[:, 1] ** 2)  # (O,)
        r = np.einsum("oki,oi->ok", self.e_h, line) / s[:, None]  # (O, 2)
        l12 = np.zeros_like(line)
        l12[:, :2] = line[:, :2] / s[:, None]
        g = (self.e_h - r[:, :, None] * l12[:, None, :]) / s[:, None, None]  # (O, 2, 3)
        alpha = cross3(w[:, None, :], g) @ self.K  # Kᵀ (w × g), row-wise: (O, 2, 3)
        beta = cross3(g, u[:, None, :]) @ self.K
        # α·(δ × R p) + β·(δ × R d) = δ·m with m = R p × α + R d × β: one m for the 3 rotation columns.
        m = cross3(Rp[:, None, :], alpha) + cross3(Rd[:, None, :], beta)  # (O, 2, 3)
        J = np.zeros((2 * n_obs, self.n_global + 4 * len(self.p0)))
        dt = self.dt[:, None]
        J[:, 0] = (np.einsum("oki,i->ok", m, a) * dt).ravel()
        a_raw = self.axis0 + x[1] * self.e_axis[0] + x[2] * self.e_axis[1]
        phi = omega * self.dt
        sin_phi, one_minus_cos = np.sin(phi)[:, None], (1 - np.cos(phi))[:, None]
        for j in range(2):
            e = self.e_axis[j]
            da = (e - a * (a @ e)) / np.linalg.norm(a_raw)
            delta = sin_phi * da + one_minus_cos * np.cross(a, da)  # (O, 3)
            J[:, 1 + j] = np.einsum("oki,oi->ok", m, delta).ravel()
        J[:, 3] = alpha[:, :, 0].ravel()
        J[:, 4] = alpha[:, :, 1].ravel()
        if self.drift:
            J[:, 5] = (dt * alpha[:, :, 0]).ravel()
            J[:, 6] = (dt * alpha[:, :, 1]).ravel()
        # Line parameters: d = normalize(d0 + f L[:2]), p = p0 + f L[2:], in the reference frame.
        L = x[self.n_global :].reshape(-1, 4)
        d_norm = np.linalg.norm(self.d0 + np.einsum("tij,tj->ti", self.f, L[:, :2]), axis=1)
        dd = (self.f - d[:, :, None] * np.einsum("ti,tij->tj", d, self.f)[:, None, :]) / d_norm[:, None, None]
        R_dd = np.einsum("oij,ojk->oik", R, dd[self.track])  # (O, 3, 2): R dd/dL_j
        R_f = np.einsum("oij,ojk->oik", R, self.f[self.track])  # (O, 3, 2): R dp/dL_j
        local = np.concatenate(
            [np.einsum("oki,oij->okj", beta, R_dd), np.einsum("oki,oij->okj", alpha, R_f)], axis=2
        )  # (O, 2, 4)
        J[self._rows, self._cols] = local
        return J
