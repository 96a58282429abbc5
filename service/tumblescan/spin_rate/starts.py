"""Where the rigid fit starts: the starts (ω, axis, c0) the multi-start (``search``) fits from.

The rigid cost has several basins on short arcs, so the fit is started from many places: the best
basins of a scan of ``rigid.scan_cost`` over rates and a sphere of axes on the longest tracks, each
polished by Nelder-Mead (with the periodogram's peaks); near the image plane, where the sphere is too
coarse and the scan misranks rates, a ladder of rates each with its best image-plane axis; and with
the axis near the line of sight, the rate at which the tracked lines turn in the image.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from .._typing import FloatArray, Progress
from ..numerics.parallel import cores, parallel_map
from .rigid import Observations, fibonacci_sphere, scan_cost

SCAN_AXES = 256
SCAN_TRACKS = 12
SCAN_CLIP_PX = 5.0
PLANE_AXIS_STEP_DEG = 6.0
PLANE_TILTS_DEG = (-8.0, 0.0, 8.0)
# With the axis near the image plane the scan misranks rates: the lines across the axis barely move
# off their image lines whatever the rate, and the linear line estimate of such a narrow pencil of
# planes is poor at the true rate, so the scan's basins all lie at slow rates with the axis tilted
# toward the line of sight (benchmark plane_101_noisy: scan cost 121 at the true rate, 39 at
# 2.3 deg/s; the converged rigid cost is lower at the true rate). A ladder of rates (ratio
# PLANE_LADDER_RATIO), each with the scan's best image-plane axis, starts short fits
# (``plane_ladder_starts``; ``search.best_of_starts`` carries the best near-plane one to convergence).
PLANE_LADDER_RATIO = 1.5
Start = tuple[float, FloatArray, FloatArray]


def scan_subset(obs: Observations) -> Observations:
    """The ``SCAN_TRACKS`` longest tracks (the scan is linear in the number of observations)."""
    lengths = np.bincount(obs.track)
    keep = np.argsort(-lengths)[:SCAN_TRACKS]
    sel = np.isin(obs.track, keep)
    remap = np.full(len(lengths), -1)
    remap[keep] = np.arange(len(keep))
    return Observations.build(remap[obs.track[sel]], obs.t_s[sel], obs.ends_px[sel], obs.K)


def plane_axes(step_deg: float = PLANE_AXIS_STEP_DEG, tilts_deg: tuple[float, ...] = PLANE_TILTS_DEG) -> FloatArray:
    """Axes (N, 3) near the image plane: every ``step_deg`` of projected direction over a full turn
    (a and -a are opposite senses), tilted by ``tilts_deg`` toward the line of sight. The sphere's
    scan is too coarse there (about 13° between axes) for a valley as narrow as the one of an axis
    that barely turns the image."""
    phi = np.radians(np.arange(0.0, 360.0, step_deg))
    out = []
    for tilt in np.radians(tilts_deg):
        c, s = np.cos(tilt), np.sin(tilt)
        out.append(np.column_stack([c * np.cos(phi), c * np.sin(phi), np.full_like(phi, s)]))
    return np.vstack(out)


def scan_starts(
    obs: Observations, omegas: FloatArray, c0: FloatArray, radius: float, t_ref: float, coarse: list[float],
    sense_hint: int, progress: Progress,
) -> list[Start]:  # fmt: skip
    """Starts (ω, axis, c0), best first: a scan over rates and axes on the longest tracks, then the
    best few basins (and the periodogram's peaks) polished by Nelder-Mead over (ω, axis, c0_xy).
    Without a sense from the image rotation (the axis may lie near the image plane) a dense set of
    image-plane axes joins the sphere."""
    sub = scan_subset(obs)
    axes = fibonacci_sphere(SCAN_AXES)
    # With a sense: the hemisphere the image rotation points to (and a band along the image plane).
    axes = axes[sense_hint * axes[:, 2] > -0.15] if sense_hint else np.vstack([axes, plane_axes()])
    C = scan_grid(sub, omegas, axes, c0, t_ref, radius)
    progress("scan", 0.7)
    cands = [(float(omegas[k]), axes[a]) for k, a in _basins(C, 3)]
    if not sense_hint:  # the best basins among the image-plane axes alone, which the sphere's outshine
        n_plane = len(plane_axes())
        cands += [(float(omegas[k]), axes[len(axes) - n_plane + a]) for k, a in _basins(C[:, -n_plane:], 2)]
    for w in coarse:
        k = int(np.argmin(np.abs(omegas - w)))
        cands.append((w, axes[int(np.argmin(C[k]))]))
    polished = parallel_map(partial(_polished, sub, c0=c0, t_ref=t_ref, radius=radius), cands)
    polished.sort(key=lambda p: p[0])
    return [(w, a, c) for _, w, a, c in polished[: 3 + (0 if sense_hint else 2)]]


def scan_grid(
    obs: Observations, omegas: FloatArray, axes: FloatArray, c0: FloatArray, t_ref: float, radius: float
) -> FloatArray:
    """``scan_cost`` (len(omegas), len(axes)) at ``SCAN_CLIP_PX``, the rates in as many blocks as
    there are cores (``numerics.parallel``)."""
    blocks = [b for b in np.array_split(omegas, min(cores(), len(omegas))) if len(b)]
    rows = parallel_map(partial(_scan_block, obs, axes=axes, c0=c0, t_ref=t_ref, radius=radius), blocks)
    return np.vstack(rows)


def _scan_block(
    obs: Observations, omegas: FloatArray, *, axes: FloatArray, c0: FloatArray, t_ref: float, radius: float
) -> FloatArray:
    return scan_cost(obs, omegas, axes, c0, t_ref, radius, clip_px=SCAN_CLIP_PX)


def _polished(
    sub: Observations, cand: tuple[float, FloatArray], *, c0: FloatArray, t_ref: float, radius: float
) -> tuple[float, float, FloatArray, FloatArray]:
    """A scan basin ``(ω, axis)`` polished by Nelder-Mead over (ω, axis, c0_xy): (cost, ω, axis, c0)."""
    from scipy.optimize import minimize

    w0, a0 = cand

    def cost(x: FloatArray) -> float:
        a = a0 + np.array([x[1], x[2], x[3]])
        a = a / np.linalg.norm(a)
        c = np.array([c0[0] + x[4], c0[1] + x[5], 1.0])
        return float(scan_cost(sub, np.array([x[0]]), a[None], c, t_ref, radius, clip_px=SCAN_CLIP_PX)[0, 0])

    x0 = np.array([w0, 0, 0, 0, 0, 0])
    simplex = x0 + np.vstack([np.zeros(6), np.diag([0.05 * w0, 0.15, 0.15, 0.15, radius * 0.2, radius * 0.2])])
    r = minimize(cost, x0, method="Nelder-Mead",
                 options={"initial_simplex": simplex, "maxfev": 250, "xatol": 1e-6, "fatol": 1e-3})  # fmt: skip
    a = a0 + r.x[1:4]
    a = a / np.linalg.norm(a)
    return float(r.fun), float(r.x[0]), a, np.array([c0[0] + r.x[4], c0[1] + r.x[5], 1.0])


def line_angle_rate_rad_s(obs: Observations) -> float | None:
    """The rate (rad/s, signed: positive turns +u toward +v, as ``sign(a·z)``) at which the tracked
    lines turn in the image: each track's line angle (mod 180°, unwrapped) fitted linearly in time,
    the median slope weighted by span. With the axis near the line of sight every line turns at about
    the spin rate, a start the scan's 6° steps and coarse axes can miss (measured: seeds 109, 115 of
    the benchmark 7.6 and 2.5 % off from the scan's starts alone). None with under 2 tracks of 3+."""
    d = obs.ends_px[:, 1] - obs.ends_px[:, 0]
    two_theta = 2.0 * np.arctan2(d[:, 1], d[:, 0])  # a line's direction is defined mod 180°
    slopes, spans = [], []
    for j in range(obs.n_tracks):
        sel = obs.track == j
        if sel.sum() < 3:
            continue
        t = obs.t_s[sel]
        order = np.argsort(t)
        ang = 0.5 * np.unwrap(two_theta[sel][order])
        tt = t[order] - t[order].mean()
        slopes.append(float(tt @ (ang - ang.mean()) / max(float(tt @ tt), 1e-12)))
        spans.append(float(np.ptp(tt)))
    if len(slopes) < 2:
        return None
    order = np.argsort(slopes)
    cum = np.cumsum(np.array(spans)[order])
    return float(np.array(slopes)[order][int(np.searchsorted(cum, 0.5 * cum[-1]))])


def plane_ladder_starts(
    obs: Observations, w_lo: float, w_hi: float, c0: FloatArray, radius: float, t_ref: float
) -> list[Start]:
    """Starts (ω, axis, c0) near the image plane over the whole rate range: rates from ``w_lo`` to
    ``w_hi`` (rad/s) in ratios of ``PLANE_LADDER_RATIO``, each with the image-plane axis
    (``plane_axes``) the scan ranks best at that rate. ``radius``: the target's radius in units of the
    range; ``c0`` (3,): the centre guess (depth 1); ``t_ref``: the reference time (s)."""
    n = int(np.floor(np.log(w_hi / w_lo) / np.log(PLANE_LADDER_RATIO))) + 1 if w_hi > w_lo else 1
    return plane_axis_starts(
        obs, np.asarray(w_lo * PLANE_LADDER_RATIO ** np.arange(n), dtype=np.float64), c0, radius, t_ref
    )


def plane_axis_starts(obs: Observations, rates: FloatArray, c0: FloatArray, radius: float, t_ref: float) -> list[Start]:
    """Starts (ω, axis, c0), one for each of ``rates`` (rad/s), with the image-plane axis
    (``plane_axes``) the scan (``scan_grid`` on ``scan_subset(obs)``) ranks best at that rate.
    ``c0`` (3,): the centre (depth 1); ``radius``: the target's radius in units of the range;
    ``t_ref``: the reference time (s)."""
    if not len(rates):
        return []
    axes = plane_axes()
    C = scan_grid(scan_subset(obs), rates, axes, c0, t_ref, radius)
    return [(float(w), axes[int(np.argmin(row))], c0) for w, row in zip(rates, C, strict=True)]


def los_start(obs: Observations, c0: FloatArray) -> Start | None:
    """A start on the line of sight at the lines' own image rotation rate (``line_angle_rate_rad_s``),
    the axis's sign its sense; None when the lines do not turn."""
    w = line_angle_rate_rad_s(obs)
    if w is None or w == 0.0:
        return None
    return abs(w), np.array([0.0, 0.0, float(np.sign(w))]), c0


def _basins(C: FloatArray, n: int) -> list[tuple[int, int]]:
    """The ``n`` best (rate index, axis index) of a scan (rates, axes), rates over 2 steps apart."""
    picks: list[tuple[int, int]] = []
    for k in np.argsort(C.min(axis=1)):
        if all(abs(k - s) > 2 for s, _ in picks):
            picks.append((int(k), int(np.argmin(C[k]))))
        if len(picks) == n:
            break
    return picks
