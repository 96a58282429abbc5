"""The choice among many starts of the rigid fit (``starts``): which fitted minimum wins.

The rigid cost has several basins on short arcs: a rate-tilt valley, half or double the rate (a
target that looks alike after half a turn), and, with the axis near the image plane, axes that
turn the image almost not at all. So the fit is started from many places, each started fit is
carried a few steps, and the winner is the one with the lowest robust cost on a common scale
(each fit's own Cauchy scale would favour a fit that calls more of the data outliers).
"""

from __future__ import annotations

import logging
from functools import partial

import numpy as np

from .._typing import FloatArray
from ..geometry.rotations import tangent_basis
from ..numerics.parallel import parallel_map
from .association import split_piecewise_tracks, without_stray_tracks
from .rigid import (
    Observations,
    RigidFit,
    cauchy_cost,
    cauchy_scale_px,
    fibonacci_sphere,
    fit_rigid,
    robust_scale_px,
    scan_cost,
)
from .rotation import los_angle_deg, mirror_twin
from .starts import SCAN_AXES, SCAN_CLIP_PX, Start, scan_subset

RATE_FACTORS = (0.5, 2.0 / 3.0, 1.5, 2.0)
SHORT_NFEV = 25
# Short fits carried to convergence; a fit within SAME_RATE_REL and SAME_AXIS_DEG of a better one
# is the same basin and not carried again.
FINALISTS = 3
SAME_RATE_REL = 0.01
SAME_AXIS_DEG = 3.0
# Converged fits this close (rate, axis with sense, cost) are one minimum reached twice (near the
# image plane two or three finalists often end there): it is restarted and polished once.
SAME_MINIMUM_REL = 1e-5
SAME_MINIMUM_AXIS_DEG = 0.01
# A fit whose lines lie mostly farther from the centre than the target's size is implausible: a
# slow rate with the lines far away mimics the image motion of a fast one near the centre.
MAX_LINE_DISTANCE_RADII = 2.0
# With the axis near the image plane the scan misranks rates (``starts.PLANE_LADDER_RATIO``): the
# best short fit from the ladder's starts (``starts.plane_ladder_starts``) with its axis within
# PLANE_FINALIST_MIN_LOS_DEG of the image plane is carried to convergence whatever its short-fit cost.
PLANE_FINALIST_MIN_LOS_DEG = 75.0
# Near-plane finalists are refitted from axes tilted this much each way (``axis_polished``).
AXIS_POLISH_DEG = 1.5
PLANE_FINALISTS = 2
# A centre velocity (2 parameters) is kept when it lowers χ² by more than this: a slow drift of the
# target across the image is otherwise absorbed by a wrong rate (measured: 1.7 and 6 % off).
DRIFT_DELTA_CHI2 = 25.0
# Rounds of cutting piecewise-rigid tracks and comparing the starts again (near the image plane).
SPLIT_ROUNDS = 3
# After a cut the previous finalists are refitted to the cut tracks; the whole multi-start is run
# again only when that moves the winner's rate by over SPLIT_RESEARCH_RATE_REL or the cuts' χ² gain
# is over SPLIT_RESEARCH_GAIN_FRAC of the winner's least-squares cost (the cut changed the problem).
SPLIT_RESEARCH_RATE_REL = 0.05
SPLIT_RESEARCH_GAIN_FRAC = 0.25
_log = logging.getLogger(__name__)


def common_costs(fits: list[RigidFit], radius: float | None = None, centre: FloatArray | None = None) -> FloatArray:
    """Each fit's Cauchy cost at one scale, the smallest of the fits' own (2 × 1.4826 × MAD, at least
    0.05 px): fits of the same observations compared alike. With ``radius`` (the target's radius in
    units of the range) and ``centre`` (its centre guess, depth 1), fits whose axis misses the
    target or whose median line lies over ``MAX_LINE_DISTANCE_RADII`` radii from the axis cost
    infinity, unless all do."""
    scale = min(cauchy_scale_px(f.residuals_px) for f in fits)
    cost = np.array([cauchy_cost(f.residuals_px, scale) for f in fits])
    if radius is not None and centre is not None:
        far = np.zeros(len(fits), dtype=bool)
        for k, f in enumerate(fits):
            miss, to_lines = centre_distance(f, centre)
            far[k] = max(miss, float(np.median(to_lines))) > MAX_LINE_DISTANCE_RADII * radius
        if not far.all():
            cost[far] = np.inf
    return cost


def centre_distance(fit: RigidFit, centre: FloatArray) -> tuple[float, FloatArray]:
    """How far the fit puts the body from the target seen in the images, in units of the range:
    the distance from ``centre`` (3,) (the target's centre guess, depth 1) to the axis line, and
    each line's distance (T,) from the axis point ``q`` nearest ``centre``. Both ignore where the
    centre sits along the axis (a gauge of the model), and both are taken with the fitted scene
    scaled so that the axis point nearest the ray through ``centre`` lies at depth 1: the images
    fix the scene only up to a scale about the camera (``c0_z = 1`` with ``c0`` free to slide
    along the axis leaves ``c0 -> λ c0 + (1 - λ) a / a_z`` free), and a fit can end anywhere along
    that family (a fit of the true motion once ended at λ = 1.16, with its axis 2.1 radii from
    the centre guess instead of 0.4)."""
    a = fit.axis
    scale = 1.0 / _depth_nearest_ray(fit.c0, a, centre)
    c0, lines_p = fit.c0 * scale, fit.lines_p * scale
    q = c0 + ((centre - c0) @ a) * a
    to_lines = np.linalg.norm(np.cross(c0 + lines_p - q, fit.lines_d), axis=1)
    return float(np.linalg.norm(centre - q)), np.asarray(to_lines, dtype=float)


def _depth_nearest_ray(c0: FloatArray, a: FloatArray, centre: FloatArray) -> float:
    """The depth of the point of the axis line ``c0 + s a`` nearest the ray through ``centre``;
    ``c0``'s own (1) when the axis runs along the ray or the point lies behind the camera."""
    u = centre / np.linalg.norm(centre)
    b = float(a @ u)
    if 1.0 - b * b < 1e-9:
        return float(c0[2])
    s = (b * float(u @ c0) - float(a @ c0)) / (1.0 - b * b)
    depth = float(c0[2] + s * a[2])
    return depth if depth > 1e-3 else float(c0[2])


def best_of_starts(
    obs: Observations, starts: list[Start], t_ref: float, w_lo: float, w_hi: float, centre: FloatArray,
    radius: float, plane_starts: list[Start] | None = None, finalists_out: list[RigidFit] | None = None,
) -> RigidFit:  # fmt: skip
    """Short fits from every start and from each one's weak-perspective twin; then from the leader
    at ``RATE_FACTORS`` times its rate (inside ``[w_lo, w_hi]``), each with the best axis of the
    scan at that rate. The ``FINALISTS`` best distinct short fits (common-scale cost) are carried to
    convergence, then the best one's weak-perspective twin, and the lowest converged cost wins.
    With ``plane_starts`` (``plane_ladder_starts``: the image does not turn) their short fits join
    (without twins: near the image plane the twin is the same axis line), and the best short fit
    with its axis near the image plane is a finalist too. ``finalists_out``, when given, is
    filled with every converged finalist (the winner among them), for ``rate_rivals``."""
    # Independent fits run side by side (numerics.parallel); the order of every list is kept.
    short = partial(_short_fit_from, obs, t_ref=t_ref)
    plane_starts = plane_starts or []
    first = parallel_map(short, [*starts, *plane_starts])
    trials = first[: len(starts)]
    trials += parallel_map(short, [(f.omega_rad_s, mirror_twin(f.axis), f.c0) for f in trials])
    trials += first[len(starts) :]
    lead = trials[int(np.argmin(common_costs(trials, radius, centre)))]
    scan_obs = scan_subset(obs)
    axes = fibonacci_sphere(SCAN_AXES)
    for factor in RATE_FACTORS:
        w = factor * lead.omega_rad_s
        if not w_lo <= w <= w_hi:
            continue
        C = scan_cost(scan_obs, np.array([w]), axes, lead.c0, t_ref, radius, clip_px=SCAN_CLIP_PX)[0]
        for a0 in (lead.axis, axes[int(np.argmin(C))]):
            trials.append(_short_fit(obs, w, a0, lead.c0, t_ref))
    # A short fit ranks basins only roughly (the one nearer its minimum after SHORT_NFEV steps looks
    # better): the best few distinct ones are carried to convergence and compared again.
    order = np.argsort(common_costs(trials, radius, centre))
    finalists: list[RigidFit] = []
    for k in order:
        if len(finalists) == FINALISTS:
            break
        if all(not same_basin(trials[k], f) for f in finalists):
            finalists.append(trials[k])
    if plane_starts:  # the best distinct near-plane short fits are finalists too
        near = [f for f in finalists if los_angle_deg(f.axis) >= PLANE_FINALIST_MIN_LOS_DEG]
        for k in order:
            if len(near) >= PLANE_FINALISTS:
                break
            f = trials[k]
            if los_angle_deg(f.axis) >= PLANE_FINALIST_MIN_LOS_DEG and all(not same_basin(f, g) for g in finalists):
                near.append(f)
                finalists.append(f)
    done = parallel_map(partial(_refit, obs, t_ref=t_ref), finalists)
    if plane_starts:
        done = _distinct_minima(parallel_map(partial(restarted, obs, t_ref=t_ref), _distinct_minima(done)))
        done = parallel_map(partial(_polished_if_near, obs, t_ref=t_ref), done)
    best = done[int(np.argmin(common_costs(done, radius, centre)))]
    # The winner's weak-perspective twin, started from the converged rate: a short fit's twin was
    # taken from a rate and axis still far off, and so may have missed the twin basin. Not when
    # another finalist already converged in that basin: the refit would only find it again
    # (measured: the same rate and cost to the printed digits).
    twin_axis = mirror_twin(best.axis)
    others = [f for f in done if f is not best]
    if not any(f.success and _near(f.omega_rad_s, f.axis, best.omega_rad_s, twin_axis) for f in others):
        done.append(fit_rigid(obs, best.omega_rad_s, twin_axis, best.c0, t_ref))
    if finalists_out is not None:
        finalists_out[:] = done
    return done[int(np.argmin(common_costs(done, radius, centre)))]


def _short_fit_from(obs: Observations, start: Start, *, t_ref: float) -> RigidFit:
    """``_short_fit`` from ``start`` (ω, axis, c0)."""
    return _short_fit(obs, *start, t_ref)


def _polished_if_near(obs: Observations, fit: RigidFit, *, t_ref: float) -> RigidFit:
    """``axis_polished`` for a fit with its axis near the image plane, else the fit."""
    return axis_polished(obs, fit, t_ref) if los_angle_deg(fit.axis) >= PLANE_FINALIST_MIN_LOS_DEG else fit


def _short_fit(obs: Observations, omega0: float, axis0: FloatArray, c0: FloatArray, t_ref: float) -> RigidFit:
    """A fit carried ``SHORT_NFEV`` steps, one robust pass, without σ: it only ranks basins."""
    return fit_rigid(obs, omega0, axis0, c0, t_ref, max_nfev=SHORT_NFEV, passes=1, uncertainty=False)


def _refit(obs: Observations, fit: RigidFit, *, t_ref: float) -> RigidFit:
    """``fit`` carried to convergence on ``obs`` from its own rate, axis, centre and drift."""
    return fit_rigid(obs, fit.omega_rad_s, fit.axis, fit.c0, t_ref, drift=fit.drift)


def restarted(obs: Observations, fit: RigidFit, t_ref: float) -> RigidFit:
    """``fit`` refitted from its own rate, axis and centre with the line structure initialised
    afresh, when that lowers the common-scale cost. Near the image plane the lines across the axis
    are a narrow pencil of planes whose structure, started from a rate and axis still far off, stays
    in a poor local minimum: on plane_101_noisy a finalist that reached the true rate and axis
    stayed at 0.23 px rms, and the slow wrong basin (0.21 px) won; restarted, 0.07-0.10 px."""
    again = fit_rigid(obs, fit.omega_rad_s, fit.axis, fit.c0, t_ref)
    cost = common_costs([fit, again])
    return again if cost[1] < cost[0] else fit


def axis_polished(obs: Observations, fit: RigidFit, t_ref: float) -> RigidFit:
    """The best (common-scale cost) of ``fit`` and fits started from its rate and centre with the
    axis tilted by ``AXIS_POLISH_DEG`` each way. Near the image plane each line's structure follows
    the axis, so a converged fit can stall 1° off the axis of a much cheaper minimum (plane_101_noisy:
    0.19 px rms 1.1° off, 0.06-0.08 px from a start 1-2° toward it)."""
    e1, e2 = tangent_basis(fit.axis)
    step = np.tan(np.radians(AXIS_POLISH_DEG))
    fits = [fit]
    for d in (e1, -e1, e2, -e2):
        a = fit.axis + step * d
        fits.append(fit_rigid(obs, fit.omega_rad_s, a / np.linalg.norm(a), fit.c0, t_ref))
    return fits[int(np.argmin(common_costs(fits)))]


def best_of_starts_without_strays(
    obs: Observations, starts: list[Start], t_ref: float, w_lo: float, w_hi: float, centre: FloatArray,
    radius: float, plane_starts: list[Start] | None = None, finalists_out: list[RigidFit] | None = None,
) -> tuple[Observations, RigidFit]:  # fmt: skip
    """``best_of_starts``; then, when its winner finds tracks that follow no rigid line (px off all
    along, ``association.without_stray_tracks``), the starts compared again without them. Such tracks
    pull every fit, a wrong basin's least (measured: two 16-frame tracks 15-25 px off the true
    motion made a fit 3.9 % off the cheaper). With ``plane_starts`` (the image does not turn: the
    axis may lie near the image plane), tracks that follow a rigid line only piecewise under the
    winner are first cut into their pieces (``association.split_piecewise_tracks``) and the starts
    compared again, up to ``SPLIT_ROUNDS`` times (the cut under a better winner finds more).
    Returns the observations kept and their fit; ``finalists_out`` as in ``best_of_starts``, from
    its last call."""
    finalists: list[RigidFit] = []
    fit = best_of_starts(obs, starts, t_ref, w_lo, w_hi, centre, radius, plane_starts, finalists)
    for _ in range(SPLIT_ROUNDS if plane_starts else 0):  # a better winner shows more switches
        gain: list[float] = []
        pieces = split_piecewise_tracks(obs, fit, t_ref, gain)
        if pieces is None:
            break
        obs = pieces
        gain_frac = gain[0] / max(float(np.sum(fit.residuals_px**2)), 1e-12)
        # The finalists refitted to the cut tracks first: a cut under a right winner (an edge bias
        # at a silhouette) leaves the ranking as it was, and the whole multi-start is not rerun. A
        # gain over SPLIT_RESEARCH_GAIN_FRAC reruns it whatever the refits give: they are skipped.
        refit, lead = None, fit
        if gain_frac <= SPLIT_RESEARCH_GAIN_FRAC:
            refit, lead = _refitted_lead(obs, finalists, t_ref, centre, radius)
        moved = np.inf if refit is None else abs(lead.omega_rad_s - fit.omega_rad_s) / max(fit.omega_rad_s, 1e-12)
        _log.debug("split: gain %.3f of cost, rate moved %.3f by the refits", gain_frac, moved)
        if refit is not None and moved <= SPLIT_RESEARCH_RATE_REL:
            finalists, fit = refit, lead
        else:
            fit = best_of_starts(obs, starts, t_ref, w_lo, w_hi, centre, radius, plane_starts, finalists)
    if finalists_out is not None:
        finalists_out[:] = finalists
    kept = without_stray_tracks(obs, fit)
    if kept is None:
        return obs, fit
    return kept, best_of_starts(kept, starts, t_ref, w_lo, w_hi, centre, radius, plane_starts, finalists_out)


def _refitted_lead(
    obs: Observations, finalists: list[RigidFit], t_ref: float, centre: FloatArray, radius: float
) -> tuple[list[RigidFit], RigidFit]:
    """``finalists`` refitted to ``obs`` from their own rate, axis and centre, and the best of them
    (common-scale cost, plausible)."""
    refit = parallel_map(partial(_refit, obs, t_ref=t_ref), finalists)
    return refit, refit[int(np.argmin(common_costs(refit, radius, centre)))]


def _distinct_minima(fits: list[RigidFit]) -> list[RigidFit]:
    """``fits`` without those that sit at the minimum of an earlier one (``SAME_MINIMUM_REL`` in
    rate and cost, ``SAME_MINIMUM_AXIS_DEG`` in axis): refitting or polishing such a copy only
    finds that minimum again."""
    cos_max = np.cos(np.radians(SAME_MINIMUM_AXIS_DEG))
    out: list[RigidFit] = []
    for f in fits:
        if not any(
            abs(f.omega_rad_s - g.omega_rad_s) <= SAME_MINIMUM_REL * max(f.omega_rad_s, g.omega_rad_s)
            and abs(f.cost - g.cost) <= SAME_MINIMUM_REL * max(f.cost, g.cost)
            and float(f.axis @ g.axis) >= cos_max
            for g in out
        ):
            out.append(f)
    return out


def same_basin(a: RigidFit, b: RigidFit) -> bool:
    """Whether two fits sit in one basin (``_near``)."""
    return _near(a.omega_rad_s, a.axis, b.omega_rad_s, b.axis)


def _near(omega_a: float, axis_a: FloatArray, omega_b: float, axis_b: FloatArray) -> bool:
    """Rates (rad/s) within ``SAME_RATE_REL`` and unit axes (with sense) within ``SAME_AXIS_DEG``."""
    same_rate = abs(omega_a - omega_b) <= SAME_RATE_REL * max(omega_a, omega_b)
    return same_rate and float(axis_a @ axis_b) >= np.cos(np.radians(SAME_AXIS_DEG))


def with_drift_if_needed(obs: Observations, fit: RigidFit, t_ref: float) -> RigidFit:
    """``fit`` refitted with a centre velocity in the image plane when that lowers
    ``χ² = 2·cost/σ²`` (common Cauchy scale, σ the moving fit's robust residual scale) by over
    ``DRIFT_DELTA_CHI2``; else ``fit``."""
    moving = fit_rigid(obs, fit.omega_rad_s, fit.axis, fit.c0, t_ref, drift=True)
    cost = common_costs([fit, moving])
    s2 = max(robust_scale_px(moving.residuals_px), 0.01) ** 2  # the larger model's, as in an F test
    return moving if 2.0 * (cost[0] - cost[1]) / s2 > DRIFT_DELTA_CHI2 else fit
