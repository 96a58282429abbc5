"""Rectification (method.md section 6): map points observed at their own times to one time.

    P(T') = O_p + R(T' - T) R(t - T)^T (P(t) - O_p)

with ``T`` the motion's reference time. Rotations are applied to the vectors directly
(Rodrigues, no per-point matrices) in chunks, so millions of points take a few passes.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import MalformedInputError, NonFiniteValueError
from ..target.motion import Motion, apply_rotation, rotation_matrices

CHUNK = 1 << 20


def rectify(
    xyz_m: ArrayLike,
    t_s: ArrayLike,
    motion: Motion,
    *,
    to_time_s: float | None = None,
) -> NDArray[np.float64]:
    """Positions at ``to_time_s`` (default: the earliest ``t_s``) of points seen at ``t_s``.

    xyz_m: ``(n, 3)`` metres, sensor frame; t_s: ``(n,)`` seconds; motion: the target's
    motion. Returns ``(n, 3)`` metres.
    """
    xyz, t = _checked(xyz_m, t_s)
    if to_time_s is None:
        to_time_s = float(t.min()) if len(t) else 0.0
    target = float(to_time_s)
    return _move(xyz, t, np.full(1, target), motion)


def distort(
    xyz_m: ArrayLike,
    t_s: ArrayLike,
    motion: Motion,
    *,
    from_time_s: float,
) -> NDArray[np.float64]:
    """Inverse of :func:`rectify`: where points known at ``from_time_s`` are at times ``t_s``."""
    xyz, t = _checked(xyz_m, t_s)
    return _move(xyz, np.full(1, from_time_s), t, motion)


def _move(
    xyz: NDArray[np.float64], t_from: NDArray[np.float64], t_to: NDArray[np.float64], motion: Motion
) -> NDArray[np.float64]:
    """``O + R(t_to) R(t_from)^T (P - O)`` where one of the two times is a single value: that
    side is one 3x3 matrix, so only the per-point side needs the Rodrigues passes."""
    x = motion.params()
    T = motion.reference_time_s
    center = np.asarray(motion.center_m)
    out = np.empty_like(xyz)
    per_point_from = len(t_from) > 1 or len(t_to) == 1
    if per_point_from:
        R_to = rotation_matrices(x, t_to[:1] - T)[0]
    else:
        R_from_T = rotation_matrices(x, t_from[:1] - T)[0].T
    for start in range(0, len(xyz), CHUNK):
        sl = slice(start, start + CHUNK)
        v = xyz[sl] - center
        if per_point_from:
            tau = t_from[sl] - T if len(t_from) > 1 else np.full(len(v), t_from[0] - T)
            out[sl] = apply_rotation(x, tau, v, inverse=True) @ R_to.T + center
        else:
            out[sl] = apply_rotation(x, t_to[sl] - T, v @ R_from_T.T) + center
    return out


def _checked(xyz_m: ArrayLike, t_s: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    xyz = np.asarray(xyz_m, dtype=float)
    t = np.asarray(t_s, dtype=float)
    if xyz.ndim != 2 or xyz.shape[1] != 3 or t.shape != (len(xyz),):
        raise MalformedInputError(f"xyz_m must be (n, 3) and t_s (n,); got {xyz.shape} and {t.shape}", field="xyz_m")
    if not (np.isfinite(xyz).all() and np.isfinite(t).all()):
        raise NonFiniteValueError("xyz_m and t_s must be finite (NaN or infinity found)", field="xyz_m")
    return xyz, t
