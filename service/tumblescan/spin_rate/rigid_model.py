"""The rigid model's parameters, residuals and analytic Jacobian (used by ``rigid.fit_rigid``).

Parameters ``x``: ``ω`` (rad/s), two axis tangents, ``c0_x, c0_y`` (units of the range), with
drift ``v_x, v_y`` (range/s), then 4 per track (2 direction tangents, 2 point offsets). For an
observation at ``dt = t_s - t_ref`` of track t: ``R = Rot(a, ω dt)``, ``X = c0 + v dt + R p_t``,
``D = R d_t``, ``u = K X``, ``w = K D``, ``l = u × w``, ``s = ‖(l₁, l₂)‖``, and the residual of
end point k is ``r_k = e_kᵀ l / s`` (px), ``e_k = (x, y, 1)``.
"""

from __future__ import annotations

from typing import Any

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
        self._f0, self._f1 = self.f[:, :, 0].copy(), self.f[:, :, 1].copy()
        self.n_global = 5 + (2 if drift else 0)
        # One rotation per frame, not per observation: every line of a frame shares its time.
        self.dt = t_s - t_ref
        self.dt_frame, self.frame_of = np.unique(self.dt, return_inverse=True)
        self.e_h = np.concatenate([ends_px, np.ones((*ends_px.shape[:2], 1))], axis=2)  # (O, 2, 3)
        n_obs = len(track)
        # Where each observation's 2 rows put their 4 line derivatives in the dense Jacobian.
        self._rows = np.repeat(np.arange(2 * n_obs).reshape(n_obs, 2)[:, :, None], 4, axis=2)
        self._cols = np.broadcast_to((self.n_global + 4 * track)[:, None, None] + np.arange(4), (n_obs, 2, 4))
        # The last evaluation's geometry: the Jacobian is taken where the residuals were just taken.
        self._cache: tuple[FloatArray, tuple[Any, ...]] | None = None

    def unpack(self, x: FloatArray) -> tuple[float, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        """``(ω, a, c0, v, p, d)`` from the parameter vector ``x``."""
        omega = float(x[0])
        a = self.axis0 + x[1] * self.e_axis[0] + x[2] * self.e_axis[1]
        a = a / np.sqrt(a @ a)
        c0 = np.array([x[3], x[4], 1.0])
        v = np.array([x[5], x[6], 0.0]) if self.drift else np.zeros(3)
        L = x[self.n_global :].reshape(-1, 4)
        d = self.d0 + self._f0 * L[:, 0:1] + self._f1 * L[:, 1:2]
        d = d / np.sqrt(np.sum(d * d, axis=1))[:, None]
        p = self.p0 + self._f0 * L[:, 2:3] + self._f1 * L[:, 3:4]
        return omega, a, c0, v, p, d

    def gauge(self, x: FloatArray) -> FloatArray:
        """The global part (1, n_global) of the model's exact null direction at ``x``. The images fix
        the scene only up to a scale: sliding the centre along the axis (``c0 + τ a``, ``p - τ a``;
        ``R a = a``) and scaling back to ``c0_z = 1`` leaves every residual unchanged, so
        ``dc0 = a - a_z c0``, ``dv = -a_z v`` (ω and the axis do not move; each line's point moves by
        ``-a - a_z p``)."""
        _, a, c0, v, *_ = self._lines(x)
        out = np.zeros((1, self.n_global))
        out[0, 3:5] = (a - a[2] * c0)[:2]
        if self.drift:
            out[0, 5:7] = -a[2] * v[:2]
        return out

    def _lines(self, x: FloatArray) -> tuple[Any, ...]:
        """At ``x``: ``(ω, a, c0, v, p, d)`` (``unpack``), then per frame R (F, 3, 3), and per
        observation R p and R d (O, 3), u = K X, w = K D, l = u × w (O, 3). The last call's result
        is kept for a call at the same ``x``."""
        if self._cache is not None and np.array_equal(self._cache[0], x):
            return self._cache[1]
        omega, a, c0, v, p, d = self.unpack(x)
        R = rot(a, omega * self.dt_frame)  # (F, 3, 3)
        n_frames = len(R)
        # Every frame's rotation of every line (F·T products in two matrix products), then each
        # observation's (frame, track) pair picked out.
        Rp = (R.reshape(3 * n_frames, 3) @ p.T).reshape(n_frames, 3, -1)[self.frame_of, :, self.track]
        Rd = (R.reshape(3 * n_frames, 3) @ d.T).reshape(n_frames, 3, -1)[self.frame_of, :, self.track]
        u = (c0 + v * self.dt[:, None] + Rp) @ self.K.T
        w = Rd @ self.K.T
        out = (omega, a, c0, v, p, d, R, Rp, Rd, u, w, cross3(u, w))
        self._cache = (x.copy(), out)
        return out

    def residuals(self, x: FloatArray) -> FloatArray:
        """The signed end-point distances (2·O,) px, observation-major."""
        line = self._lines(x)[-1]
        line = line / np.sqrt(line[:, 0] * line[:, 0] + line[:, 1] * line[:, 1])[:, None]
        return np.asarray(self._ends_dot(line).ravel())

    def _ends_dot(self, line: FloatArray) -> FloatArray:
        """``e_kᵀ l`` (O, 2) for each observation's end points ``e_k = (x, y, 1)`` and line ``l`` (O, 3)
        (written out: ``np.einsum`` costs more on these small arrays)."""
        e = self.e_h
        return np.asarray(e[..., 0] * line[:, None, 0] + e[..., 1] * line[:, None, 1] + line[:, None, 2])

    def jacobian(self, x: FloatArray) -> FloatArray:
        """The analytic Jacobian (2·O, P) of ``residuals``: globals first, then 4 columns per track
        (``jacobian_blocks`` written into one dense matrix)."""
        J_global, J_line = self.jacobian_blocks(x)
        n_obs = len(self.track)
        J = np.zeros((2 * n_obs, self.n_global + 4 * len(self.p0)))
        J[:, : self.n_global] = J_global
        J[self._rows, self._cols] = J_line.reshape(n_obs, 2, 4)
        return J

    def jacobian_blocks(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The analytic Jacobian of ``residuals`` in its two blocks: the global columns (2·O, n_global)
        and each row's 4 columns of its own track's line (2·O, 4); every other entry is zero.

        ``dr_k = g_k·dl`` with ``g_k = (e_k - r_k (l₁, l₂, 0)/s) / s``, and ``dl = (K dX) × w + u × (K dD)``,
        so ``dr_k = α_k·dX + β_k·dD`` with ``α_k = Kᵀ (w × g_k)``, ``β_k = Kᵀ (g_k × u)``. A rotation
        change ``dR = [δ]× R`` gives ``dX = δ × R p``, ``dD = δ × R d``: for ω, ``δ = dt a``; for the
        axis (``da`` tangent to the unit ``a``, ``φ = ω dt``) the SO(3) left Jacobian gives
        ``δ = sin φ da + (1 - cos φ) a × da``."""
        omega, a, _, _, _, d, R_frame, Rp, Rd, u, w, line = self._lines(x)
        n_obs = len(self.track)
        e = self.e_h
        s = np.sqrt(line[:, 0] ** 2 + line[:, 1] ** 2)  # (O,)
        r = self._ends_dot(line) / s[:, None]  # (O, 2)
        l12 = np.zeros_like(line)
        l12[:, :2] = line[:, :2] / s[:, None]
        g = (e - r[:, :, None] * l12[:, None, :]) / s[:, None, None]  # (O, 2, 3)
        # α = Kᵀ (w × g), β = Kᵀ (g × u), row-wise (one matrix product for all (O·2) rows).
        alpha = (cross3(w[:, None, :], g).reshape(-1, 3) @ self.K).reshape(n_obs, 2, 3)
        beta = (cross3(g, u[:, None, :]).reshape(-1, 3) @ self.K).reshape(n_obs, 2, 3)
        # α·(δ × R p) + β·(δ × R d) = δ·m with m = R p × α + R d × β: one m for the 3 rotation columns.
        m = cross3(Rp[:, None, :], alpha) + cross3(Rd[:, None, :], beta)  # (O, 2, 3)
        # The rotation columns: δ = dt a for ω; for the axis (da tangent to the unit a, φ = ω dt)
        # δ = sin φ da + (1 - cos φ) a × da.
        a_raw = self.axis0 + x[1] * self.e_axis[0] + x[2] * self.e_axis[1]
        a_norm = float(np.sqrt(a_raw @ a_raw))
        phi = omega * self.dt
        sin_phi, one_minus_cos = np.sin(phi)[:, None], (1 - np.cos(phi))[:, None]
        deltas = [self.dt[:, None] * a]
        for j in range(2):
            ej = self.e_axis[j]
            da = (ej - a * (a @ ej)) / a_norm
            deltas.append(sin_phi * da + one_minus_cos * cross3(a, da))  # (O, 3)
        J = np.empty((2 * n_obs, self.n_global))
        J[:, :3] = (m @ np.stack(deltas, axis=2)).reshape(2 * n_obs, 3)
        J[:, 3] = alpha[:, :, 0].ravel()
        J[:, 4] = alpha[:, :, 1].ravel()
        if self.drift:
            J[:, 5] = (self.dt[:, None] * alpha[:, :, 0]).ravel()
            J[:, 6] = (self.dt[:, None] * alpha[:, :, 1]).ravel()
        # Line parameters: d = normalize(d0 + f L[:2]), p = p0 + f L[2:], in the reference frame;
        # β·(R dd/dL) and α·(R dp/dL) as ([β; α] R) [dd/dL | dp/dL], one (4 x 4) per observation.
        L = x[self.n_global :].reshape(-1, 4)
        d_raw = self.d0 + self._f0 * L[:, 0:1] + self._f1 * L[:, 1:2]
        d_norm = np.sqrt(np.sum(d_raw * d_raw, axis=1))
        dd = (self.f - d[:, :, None] * (d[:, None, :] @ self.f)) / d_norm[:, None, None]  # (T, 3, 2)
        M = np.concatenate([dd, self.f], axis=2)  # (T, 3, 4)
        Q = np.concatenate([beta, alpha], axis=1) @ R_frame[self.frame_of]  # (O, 4, 3)
        full = Q @ M[self.track]  # (O, 4, 4)
        local = np.concatenate([full[:, :2, :2], full[:, 2:, 2:]], axis=2)  # (O, 2, 4)
        return J, local.reshape(2 * n_obs, 4)
