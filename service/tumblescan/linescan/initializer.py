"""Closed-form cone initializer (method.md section 5, beyond the paper).

For frames taken at ``t_k`` and ``t_k + dt`` the inter-frame rotation is

    R_k = R(t_k + dt) R(t_k)^T = Rp(dt) Rot(l_s(t_k), w_s dt)

and ``R_{k+1} = Rp(dt) R_k Rp(dt)^T``: the rotation axes of successive ``R_k`` sweep a cone
about ``l_p`` at ``w_p`` with a constant rotation angle. So:

1. ``R_k, t_k`` from a rigid (Kabsch) fit of the features shared by frames ``k, k+1``;
2. ``l_p`` = normal of the plane through the axis tips, ``w_p`` = their angular step / dt;
3. ``Rot(l_s(t_k), w_s dt) = Rp(dt)^T R_k`` gives ``l_s(t_k)`` (mapped back to ``T``) and ``w_s``;
4. ``O_p`` from ``t_k = (I - R_k) O_p`` by linear least squares.

A line-scan frame is not a snapshot: its features are seen at different times. Each pass
therefore re-times every observation to its frame's mean time with the previous estimate
(``transport``) and repeats the four steps; a few passes converge.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray
from ..geometry.rotations import angles_from_axis, rotate, rotation_matrix
from ..target.motion import rotation_matrices, transport
from .tracks import Tracks

RETIME_PASSES = 4
# Stop re-timing once the rotational parameters move less than this (radians, rad/s).
RETIME_TOL = 1e-4
# Below this spread of the rotation-axis tips (radians) the cone has collapsed: no
# precession is visible and the spin-only start is used.
MIN_CONE_SPREAD_RAD = 1e-6
# Scale of the robust loss polishing the cone on measured transforms (radians).
POLISH_SCALE_RAD = np.radians(0.5)


class InitializerError(RuntimeError):
    """The data do not support the closed-form start (too few shared features, a degenerate cone)."""


@dataclass(frozen=True)
class InitialGuess:
    """Starting values: the full 9-vector and the spin-only 9-vector (precession rate 0)."""

    x: FloatArray
    x_spin_only: FloatArray
    cone_collapsed: bool
    passes: int


def kabsch_batch(a: list[FloatArray], b: list[FloatArray]) -> tuple[FloatArray, FloatArray]:
    """Kabsch for many point-set pairs at once (one batched SVD): ``R (P, 3, 3), t (P, 3)``."""
    ca = np.array([p.mean(axis=0) for p in a])
    cb = np.array([p.mean(axis=0) for p in b])
    H = np.array([(p - c).T @ (q - d) for p, q, c, d in zip(a, b, ca, cb, strict=True)])
    U, _, Vt = np.linalg.svd(H)
    V = Vt.transpose(0, 2, 1)
    d = np.sign(np.linalg.det(V @ U.transpose(0, 2, 1)))
    D = np.zeros_like(H)
    D[:, 0, 0] = D[:, 1, 1] = 1.0
    D[:, 2, 2] = d
    R = V @ D @ U.transpose(0, 2, 1)
    t = cb - np.einsum("pij,pj->pi", R, ca)
    return R, t


def axis_angle(R: FloatArray) -> tuple[FloatArray, float]:
    """Unit axis and angle in ``[0, pi]`` of a rotation matrix."""
    angle = float(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0)))
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    n = np.linalg.norm(w)
    if n < 1e-12:
        # Near 0 or pi: the axis is the eigenvector of the largest diagonal of R + I.
        S = R + np.eye(3)
        axis = S[:, int(np.argmax(np.diag(S)))]
        return axis / np.linalg.norm(axis), angle
    return w / n, angle


def _frame_pairs(tracks: Tracks, xyz: FloatArray) -> list[tuple[int, FloatArray, FloatArray]]:
    """For each frame pair (k, k+1) with >= 3 shared tracks: (k, positions in k, in k+1)."""
    pairs = []
    n_f = tracks.n_frames
    table = np.full((n_f, tracks.n_tracks), -1)
    table[tracks.frame, tracks.track] = np.arange(len(tracks))
    for k in range(n_f - 1):
        shared = (table[k] >= 0) & (table[k + 1] >= 0)
        if shared.sum() >= 3:
            pairs.append((k, xyz[table[k, shared]], xyz[table[k + 1, shared]]))
    return pairs


def cone_initial(tracks: Tracks, reference_time_s: float) -> InitialGuess:
    """Closed-form starting values for the 9 motion parameters (see the module docstring)."""
    t_frame = tracks.frame_times_s()
    xyz = tracks.xyz_m
    x: FloatArray | None = None
    guess: InitialGuess | None = None
    for p in range(RETIME_PASSES):
        if x is not None:
            # Re-time every observation to its frame's mean time with the current estimate.
            xyz = np.asarray(
                transport(x, tracks.xyz_m, tracks.t_s - reference_time_s, t_frame[tracks.frame] - reference_time_s)
            )
        guess = _one_pass(tracks, xyz, t_frame, reference_time_s, passes=p + 1)
        converged = x is not None and np.max(np.abs(np.sin((guess.x[:6] - x[:6]) / 2))) < RETIME_TOL
        x = guess.x
        if converged:
            break
    assert guess is not None
    return guess


def _one_pass(
    tracks: Tracks, xyz: FloatArray, t_frame: FloatArray, reference_time_s: float, passes: int
) -> InitialGuess:
    pairs = _frame_pairs(tracks, xyz)
    if len(pairs) < 3:
        raise InitializerError(f"only {len(pairs)} frame pair(s) share 3 or more features; the cone needs 3")
    Rs, ts = kabsch_batch([a for _, a, _ in pairs], [b for _, _, b in pairs])
    ks = np.array([k for k, _, _ in pairs])
    return cone_from_transforms(Rs, ts, t_frame[ks], t_frame[ks + 1], reference_time_s, passes=passes)


def cone_from_transforms(
    Rs: FloatArray, ts: FloatArray, t_from_s: FloatArray, t_to_s: FloatArray, reference_time_s: float, passes: int = 1
) -> InitialGuess:
    """Steps 2-4 of the module docstring from rigid transforms ``p(t_to) = R_k p(t_from) + t_k``.

    Rs: ``(P, 3, 3)``; ts: ``(P, 3)`` metres; t_from_s, t_to_s: ``(P,)`` seconds, in time order.
    """
    if len(Rs) < 3:
        raise InitializerError(f"{len(Rs)} inter-frame transform(s); the cone needs 3")
    t_k = np.asarray(t_from_s, dtype=float)
    dt = np.asarray(t_to_s, dtype=float) - t_k
    axes_angles = [axis_angle(R) for R in Rs]
    axes = np.array([aa[0] for aa in axes_angles])
    angles = np.array([aa[1] for aa in axes_angles])
    center = center_from_transforms(Rs, ts)
    x_spin = _spin_only(axes, angles, dt, center)

    # 2. Precession axis: normal of the plane through the tips of the rotation axes.
    tips = axes - axes.mean(axis=0)
    spread = float(np.sqrt(np.mean(np.sum(tips**2, axis=1))))
    if spread < MIN_CONE_SPREAD_RAD:
        return InitialGuess(x=_with_small_precession(x_spin), x_spin_only=x_spin, cone_collapsed=True, passes=passes)
    l_p = np.linalg.svd(tips)[2][-1]
    # 2b. Precession rate: signed step of the tips about l_p per second.
    proj = axes - np.outer(axes @ l_p, l_p)
    a, b = proj[:-1], proj[1:]
    step = np.arctan2(np.cross(a, b) @ l_p, np.sum(a * b, axis=1))
    gap = t_k[1:] - t_k[:-1]
    w_p = float(np.sum(step * gap) / np.sum(gap**2))
    # 3. Spin: remove the precession step from each R_k, map the spin axis back to T.
    spin_axes = []
    spin_rates = []
    for R, tk, d in zip(Rs, t_k, dt, strict=True):
        l_s_k, ang = axis_angle(rotation_matrix(l_p, -w_p * d) @ R)
        spin_axes.append(rotate(l_p, -w_p * (tk - reference_time_s), l_s_k))
        spin_rates.append(ang / d)
    spin_axes_a = np.array(spin_axes)
    # Sign-align before averaging: axis-angle extraction returns angles in [0, pi].
    spin_axes_a *= np.sign(spin_axes_a @ spin_axes_a[0])[:, None]
    l_s = spin_axes_a.mean(axis=0)
    a_s, b_s = angles_from_axis(l_s)
    a_p, b_p = angles_from_axis(l_p)
    x = np.array([a_s, b_s, float(np.median(spin_rates)), a_p, b_p, w_p, *center])
    return InitialGuess(x=x, x_spin_only=x_spin, cone_collapsed=False, passes=passes)


def center_from_transforms(Rs: FloatArray, ts: FloatArray) -> FloatArray:
    """``O_p`` from ``t_k = (I - R_k) O_p`` (minimum-norm when the axes are all parallel)."""
    A = (np.eye(3) - Rs).reshape(-1, 3)
    return np.asarray(np.linalg.lstsq(A, ts.reshape(-1), rcond=None)[0], dtype=float)


def _spin_only(axes: FloatArray, angles: FloatArray, dt: FloatArray, center: FloatArray) -> FloatArray:
    aligned = axes * np.sign(axes @ axes[0])[:, None]
    a_s, b_s = angles_from_axis(aligned.mean(axis=0))
    return np.array([a_s, b_s, float(np.median(angles / dt)), 0.0, 0.0, 0.0, *center])


def _with_small_precession(x_spin: FloatArray) -> FloatArray:
    """A full-model start near a pure spin: precession axis across the spin axis, rate ~0."""
    x = x_spin.copy()
    x[3], x[4] = x[0] + np.pi / 2, np.pi / 2
    x[5] = 1e-3
    return x


def motion_from_transforms(
    Rs: FloatArray, ts: FloatArray, t_from_s: FloatArray, t_to_s: FloatArray, reference_time_s: float
) -> InitialGuess:
    """The cone start (:func:`cone_from_transforms`) polished by a robust least-squares fit of
    the six rotational parameters to the transforms.

    The closed-form cone is exact for exact transforms, but its precession axis (the normal of
    the plane through the rotation-axis tips) degrades quickly when the transforms carry
    errors of a fraction of a degree, as registrations of dense frames do. The polish minimizes
    ``sum_k rho(|log(R_k(x)^T R_k)|)`` (soft-L1 at ``POLISH_SCALE_RAD``) from the cone and
    from the spin-only start, and keeps the better.
    """
    from scipy.optimize import least_squares
    from scipy.spatial.transform import Rotation

    cone = cone_from_transforms(Rs, ts, t_from_s, t_to_s, reference_time_s)
    tau_from = np.asarray(t_from_s, dtype=float) - reference_time_s
    tau_to = np.asarray(t_to_s, dtype=float) - reference_time_s

    def residuals(rot: FloatArray) -> FloatArray:
        x = np.concatenate([rot, cone.x[6:9]])
        predicted = rotation_matrices(x, tau_to) @ np.swapaxes(rotation_matrices(x, tau_from), 1, 2)
        return np.asarray(Rotation.from_matrix(np.swapaxes(predicted, 1, 2) @ Rs).as_rotvec().ravel())

    best = None
    for start in (cone.x[:6], _with_small_precession(cone.x_spin_only)[:6]):
        sol = least_squares(residuals, start, loss="soft_l1", f_scale=POLISH_SCALE_RAD)
        if best is None or sol.cost < best.cost:
            best = sol
    assert best is not None
    x = np.concatenate([best.x, cone.x[6:9]])
    return InitialGuess(x=x, x_spin_only=cone.x_spin_only, cone_collapsed=cone.cone_collapsed, passes=cone.passes)
