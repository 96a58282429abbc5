"""The spin of a target from an image sequence: the recipe (ours, or the paper's)."""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray, Progress, no_progress
from .association import drop_stray_tracks, reject_outliers, rematch
from .coarse import lomb_scargle_peaks, mask_orientation
from .errors import NotConvergedError, TooFewFeaturesError, UndersampledError
from .features import Features, extract
from .meta import SpinInput
from .options import EstimateOptions
from .result import AxisCandidate, FrameInfo, Quality, Spin, SpinResult, TrackObs
from .rigid import Observations, RigidFit, fit_rigid
from .rivals import peak_fits, rate_rivals, sigma_with_rivals
from .rotation import los_angle_deg, mirror_twin, projected_angle_deg
from .search import best_of_starts_without_strays, common_costs, with_drift_if_needed
from .starts import los_start, plane_ladder_starts, scan_starts
from .tracking import TURNING_MIN_DEG

MIN_TRACK_FRAMES = 3
LONG_TRACK_FRAMES = 6
DEFAULT_MAX_STEP_DEG = 90.0
TRACKING_MAX_STEP_DEG = 60.0
STATIC_MOTION_PX = 0.5
SENSE_MIN_FROM_PLANE_DEG = 15.0
TWIN_DELTA_CHI2 = 9.0
SCAN_STEP_DEG = 6.0
N_PERIODOGRAM_PEAKS = 2
RATE_SIGMA_FLOOR_REL = 0.0015
IMG_RATE_MAX_FACTOR = 2.5
REMATCH_ROUNDS = 3
LOS_START_MAX_DEG = 30.0
# Within this much of the image plane a rival rate the data do not rule out (rivals.rate_rivals) is
# reported, and σ widened to cover it: there the rate rests on short arcs of the edges along the
# axis (the sense is not reported there either: SENSE_MIN_FROM_PLANE_DEG).
RATE_RIVAL_PLANE_DEG = 15.0
MAX_RATE_RIVALS = 2


@dataclass(frozen=True)
class Sequence:
    """Validated frames in memory: grayscale images (DN), times, the full scale and meta.json."""

    grays: list[FloatArray]
    t_s: FloatArray
    full_scale: float
    meta: SpinInput


def estimate_spin(
    seq: Sequence, options: EstimateOptions | None = None, progress: Progress = no_progress
) -> SpinResult:
    """The recipe: refuse aliasing priors, find the target and its straight edges, track them,
    then fit one rotation to every track (or the paper's sine fit)."""
    opts = options or EstimateOptions()
    clock = {"start": time.perf_counter()}
    t, meta = seq.t_s, seq.meta
    # 1. Sampling: refuse a prior that admits aliases; without one, assume under 90° per interval.
    dt_med = float(np.median(np.diff(t)))
    flags: list[str] = []
    max_rate = meta.prior.max_rate_deg_s
    if max_rate is not None and max_rate * dt_med >= 180.0:
        raise UndersampledError(
            f"prior.max_rate_deg_s: {max_rate} deg/s over a median interval of {dt_med:.4g} s is "
            f"{max_rate * dt_med:.0f}° per frame (>= 180°): aliased rates cannot be told apart",
            field="prior.max_rate_deg_s",
        )
    if max_rate is None:
        flags.append("alias_unchecked")
        max_rate = DEFAULT_MAX_STEP_DEG / dt_med
    # 2-3. Target masks, LSD segments, line tracks.
    feats = extract(seq.grays, seq.full_scale, meta.prior.target_polarity, progress, t)
    clock["features"] = time.perf_counter()
    tracks = [tr for tr in feats.tracks if len(tr) >= MIN_TRACK_FRAMES]
    if len(tracks) < 2:
        raise TooFewFeaturesError(
            f"frames: {len(tracks)} line tracks of 3 or more frames (at least 2 spanning 6 frames are needed)",
            field="frames",
        )
    obs = _observations(seq, feats, tracks)
    # 4. Static target: no edge moves above the noise.
    motion = _track_motion_px(obs)
    if motion < STATIC_MOTION_PX:
        return _static_result(seq, feats, obs, motion, flags, clock)
    if opts.method == "paper":
        from .paper import paper_fit

        return paper_fit(seq, feats, tracks, obs, flags, clock, max_rate)
    # 5. Coarse rate: Lomb-Scargle of the mask orientation, and a scan of (rate, axis).
    w_lo = np.radians(max(meta.prior.min_rate_deg_s or 0.0, 0.5 * 360.0 / (t[-1] - t[0]) / 20.0))
    w_hi = np.radians(min(max_rate, TRACKING_MAX_STEP_DEG / dt_med))
    span = float(t[-1] - t[0])
    # The frame-to-frame image rotation (clockwise as displayed) bounds the rate when the axis is
    # off the image plane: ω between 0.6 and 2.5 times it, and its sign is the sense, sign(a·z).
    img_rate = float(np.median([r / (t[l_] - t[k]) for (k, l_), r in feats.rotation_deg.items()]))
    sense_hint = 0
    if abs(img_rate) * dt_med > TURNING_MIN_DEG:
        sense_hint = int(np.sign(img_rate))
        w_lo = max(w_lo, np.radians(0.6 * abs(img_rate)))
        w_hi = min(w_hi, np.radians(IMG_RATE_MAX_FACTOR * abs(img_rate)))
    omegas = np.arange(w_lo, max(w_hi, w_lo * 1.01), np.radians(SCAN_STEP_DEG) / span)
    found = [k for k, tg in enumerate(feats.targets) if tg.mask is not None]
    psi = np.array([mask_orientation(feats.targets[k].mask) for k in found])  # type: ignore[arg-type]
    peaks = lomb_scargle_peaks(t[found], psi, omegas, N_PERIODOGRAM_PEAKS)
    coarse = peaks[0] if peaks else None
    c0 = _centre_guess(seq, feats)
    radius = _radius_guess(seq, feats)
    starts = scan_starts(obs, omegas, c0, radius, t[0], peaks, sense_hint, progress)
    # The scan's best axis near the line of sight: one more start on it at the lines' own rate. Not
    # for an oblique axis, where lines turn slower than the body (benchmark oblique_116_clean: a
    # start at that rate led to a cheaper basin 45 % off).
    on_los = los_start(obs, c0) if sense_hint and los_angle_deg(starts[0][1]) <= LOS_START_MAX_DEG else None
    if on_los is not None and w_lo <= on_los[0] <= w_hi:
        starts.append(on_los)
    # The image does not turn: the axis may lie near the image plane, where the scan ranks rates
    # poorly; a ladder of rates with image-plane axes starts more fits (starts.plane_ladder_starts).
    plane = None if sense_hint else plane_ladder_starts(obs, w_lo, w_hi, c0, radius, t[0])
    clock["scan"] = time.perf_counter()
    # 6. Short rigid fits from each start (and their twins, and the leader at simple multiples of
    # its rate), the best carried on, and again without tracks that follow no rigid line; peel the
    # outliers; re-match every frame's segments to its lines and refit.
    finalists: list[RigidFit] = []
    obs, fit = best_of_starts_without_strays(obs, starts, t[0], w_lo, w_hi, c0, radius, plane, finalists)
    obs, fit = reject_outliers(obs, fit, t[0])
    fit = with_drift_if_needed(obs, fit, t[0])
    progress("fit", 0.85)
    ideal = [np.array([seq.meta.pinhole.undistort(e) for e in segs.ends_px]) for segs in feats.segments]
    for _ in range(REMATCH_ROUNDS):  # a better model matches more segments, until it stops growing
        obs2 = rematch(ideal, t, fit, obs, seq.meta.pinhole.K)
        if obs2 is None or len(obs2.track) < 0.8 * len(obs.track):
            break
        fit = fit_rigid(obs2, fit.omega_rad_s, fit.axis, fit.c0, t[0], drift=fit.drift)
        obs, fit = reject_outliers(obs2, fit, t[0])
    obs, fit = drop_stray_tracks(obs, fit, t[0])
    # The rule of the contract, on the final tracks: at least 2 spanning 6 or more frames.
    frame_of = _frame_of(seq, obs)
    spans = [int(np.ptp(frame_of[obs.track == j])) + 1 for j in range(obs.n_tracks)]
    if sum(s >= LONG_TRACK_FRAMES for s in spans) < 2:
        raise TooFewFeaturesError(
            f"frames: {sum(s >= LONG_TRACK_FRAMES for s in spans)} line tracks span 6 or more frames "
            "(at least 2 are needed)",
            field="frames",
        )
    if not np.isfinite(fit.sigma_omega_rad_s) or not np.isfinite(fit.omega_rad_s):
        raise NotConvergedError("frames: the rigid fit did not converge (sigma not finite)", field="frames")
    # 7. The image does not turn: the search may have ended in a slow basin while a cheaper one lies
    # at the mask periodogram's peak; fits from the peaks on the final tracks, the cheapest wins.
    if not sense_hint:
        at_peaks = peak_fits(obs, fit, peaks, t[0], radius)
        best = int(np.argmin(common_costs([fit, *at_peaks], radius, c0)))
        finalists += [fit, *at_peaks]
        fit = [fit, *at_peaks][best]
    # 8. The weak-perspective twin: refit from (-a_x, -a_y, a_z); ambiguous when as good.
    twin = fit_rigid(obs, fit.omega_rad_s, mirror_twin(fit.axis), fit.c0, t[0], drift=fit.drift)
    s2 = max(fit.rms_px**2, 1e-6)
    if twin.cost < fit.cost:
        fit, twin = twin, fit
    ambiguous = 2 * (twin.cost - fit.cost) / s2 < TWIN_DELTA_CHI2
    # 9. Near the image plane: rival rates the data do not rule out (reported, σ covers them). Also
    # when the image does not turn whatever axis won: a collapsed fit's axis is often tilted 20-60°
    # toward the line of sight (benchmark plane_100_noisy), out of the 15° band.
    rivals: list[RigidFit] = []
    if not sense_hint or 90.0 - los_angle_deg(fit.axis) <= RATE_RIVAL_PLANE_DEG:
        rivals = rate_rivals(obs, fit, finalists, t[0], c0, radius)[:MAX_RATE_RIVALS]
    clock["fit"] = time.perf_counter()
    return _result(seq, feats, obs, fit, twin if ambiguous else None, coarse, flags, clock, rivals)


def _observations(seq: Sequence, feats: Features, tracks: list) -> Observations:
    cam = seq.meta.pinhole
    trk, tt, ends, frames = [], [], [], []
    for j, tr in enumerate(tracks):
        for f, i in sorted(tr.members.items()):
            trk.append(j)
            tt.append(seq.t_s[f])
            ends.append(cam.undistort(feats.segments[f].ends_px[i]))
            frames.append(f)
    obs = Observations.build(np.array(trk), np.array(tt), np.array(ends), cam.K)
    return obs


def _frame_of(seq: Sequence, obs: Observations) -> np.ndarray:
    return np.searchsorted(seq.t_s, obs.t_s)


def _track_motion_px(obs: Observations) -> float:
    """Median over tracks of the largest distance of an end point to the track's first line (px)."""
    out = []
    for j in range(obs.n_tracks):
        e = obs.ends_px[obs.track == j]
        p, q = e[0]
        d = (q - p) / np.linalg.norm(q - p)
        n = np.array([-d[1], d[0]])
        out.append(float(np.max(np.abs((e.reshape(-1, 2) - p) @ n))))
    return float(np.median(out))


def _centre_guess(seq: Sequence, feats: Features) -> FloatArray:
    """The projected centre of rotation (normalised, z = 1): the median fixed point of the
    frame-to-frame affines that turn by over 3° (the centroid of an unequal, partly shadowed target
    is often 10+ px off it), else the mean mask centroid."""
    K = seq.meta.pinhole.K
    fixed = []
    for (k, l_), A in feats.affines.items():
        if abs(feats.rotation_deg[(k, l_)]) > 3.0:
            M = A[:, :2] - np.eye(2)
            if abs(np.linalg.det(M)) > 1e-3:
                fixed.append(np.linalg.solve(M, -A[:, 2]))
    if len(fixed) >= 3:
        u, v = np.median(np.array(fixed), axis=0)
    else:
        cents = np.array([tg.centroid_px for tg in feats.targets if tg.centroid_px is not None])
        u, v = cents.mean(axis=0)
    return np.array([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], 1.0])


def _radius_guess(seq: Sequence, feats: Features) -> float:
    """The target's radius in units of the range (from the largest mask's extent)."""
    ext = max(np.hypot(tg.bbox[2] - tg.bbox[0], tg.bbox[3] - tg.bbox[1]) for tg in feats.targets if tg.bbox)
    return float(0.5 * ext / seq.meta.pinhole.focal_px)


def _quality_common(seq: Sequence, feats: Features, obs: Observations, flags: list[str]) -> tuple[list[str], int]:
    t = seq.t_s
    if any(tg.touches_border for tg in feats.targets):
        flags.append("target_touches_border")
    if any(tg.saturated for tg in feats.targets):
        flags.append("saturated")
    if obs.n_tracks < 4:
        flags.append("few_tracks")
    return flags, int(sum(tg.found for tg in feats.targets)) if len(t) else 0


def _frames_info(seq: Sequence, feats: Features, obs: Observations, resid: FloatArray | None) -> list[FrameInfo]:
    fr = _frame_of(seq, obs)
    out = []
    for k, tg in enumerate(feats.targets):
        here = fr == k
        rms = None
        if resid is not None and here.any():
            rms = round(float(np.sqrt(np.mean(resid.reshape(-1, 2)[here] ** 2))), 4)
        out.append(FrameInfo(
            index=k, t_s=float(seq.t_s[k]), target_found=tg.found, target_area_px=tg.area_px,
            centroid_px=None if tg.centroid_px is None else [round(float(x), 3) for x in tg.centroid_px],
            lines=len(feats.segments[k]), tracked=int(here.sum()), rms_px=rms,
        ))  # fmt: skip
    return out


def _tracks_out(seq: Sequence, obs: Observations, resid: FloatArray | None) -> list[TrackObs] | None:
    fr = _frame_of(seq, obs)
    r = resid.reshape(-1, 2) if resid is not None else np.zeros((len(obs.track), 2))
    return [
        TrackObs(track=int(j), frame=int(f), ends_px=np.round(e, 3).tolist(), residuals_px=np.round(rr, 4).tolist())
        for j, f, e, rr in zip(obs.track, fr, obs.ends_px, r, strict=True)
    ]


def _timings(clock: dict[str, float]) -> dict[str, float]:
    end = time.perf_counter()
    keys = list(clock)
    out = {}
    for a, b in itertools.pairwise(keys):
        out[b] = round(1000 * (clock[b] - clock[a]), 1)
    out["total"] = round(1000 * (end - clock["start"]), 1)
    return out


def _sampling(seq: Sequence, rate_deg_s: float) -> tuple[float, float, float]:
    t = seq.t_s
    dt_med = float(np.median(np.diff(t)))
    return rate_deg_s * (t[-1] - t[0]) / 360.0, rate_deg_s * dt_med, 180.0 / dt_med


def _result(
    seq: Sequence, feats: Features, obs: Observations, fit: RigidFit, twin: RigidFit | None, coarse: float | None,
    flags: list[str], clock: dict[str, float], rivals: list[RigidFit] | None = None,
) -> SpinResult:  # fmt: skip
    rate = float(np.degrees(fit.omega_rad_s))
    # Edge biases that move with the lighting are not in the residuals; a relative floor, measured
    # on the simulator benchmark (docs/spin_rate.md), keeps σ from being overconfident. The derived
    # σ alone (formal, per-track sandwich, track jackknife) covered 87 % there, short of 95 %.
    sigma = float(np.hypot(np.degrees(fit.sigma_omega_rad_s), RATE_SIGMA_FLOOR_REL * rate))
    rivals = rivals or []
    sigma = sigma_with_rivals(sigma, rate, [float(np.degrees(r.omega_rad_s)) for r in rivals])
    a = fit.axis
    min_rate = seq.meta.prior.min_rate_deg_s
    spinning = not (min_rate is not None and rate < min_rate)
    los = los_angle_deg(a)
    sense = int(np.sign(a[2])) if 90.0 - los > SENSE_MIN_FROM_PLANE_DEG else None
    revs, step, nyq = _sampling(seq, rate)
    flags, n_found = _quality_common(seq, feats, obs, flags)
    if revs < 0.25:
        flags.append("short_arc")
    if twin is not None:
        flags.append("weak_perspective")
    if rivals:
        flags.append("rate_ambiguous")
    candidates = (
        []
        if twin is None
        else [
            AxisCandidate(
                axis_camera=[round(float(x), 6) for x in twin.axis], kind="mirror", cost=round(twin.cost / fit.cost, 4)
            )
        ]
    )
    candidates += [
        AxisCandidate(
            axis_camera=[round(float(x), 6) for x in r.axis],
            kind="rate",
            cost=round(_cost_ratio(r, fit), 4),
            rate_deg_s=round(float(np.degrees(r.omega_rad_s)), 6),
        )
        for r in rivals
    ]
    sig_axis = float(np.degrees(np.sqrt(max(np.trace(fit.cov_axis_rad2), 0.0))))
    period = 360.0 / rate if rate > 0 else None
    spin = Spin(
        spinning=spinning, rate_deg_s=round(rate, 6), sigma_rate_deg_s=round(sigma, 6),
        rate_rad_s=round(fit.omega_rad_s, 8), period_s=None if period is None else round(period, 6),
        sigma_period_s=None if period is None else round(period * sigma / rate, 6),
        sense_about_los=sense if spinning else None,
        axis_camera=[round(float(x), 6) for x in a] if spinning else None,
        sigma_axis_deg=round(sig_axis, 4) if spinning else None, axis_ambiguous=twin is not None,
        axis_candidates=candidates,
        axis_los_angle_deg=round(los, 4) if spinning else None,
        projected_axis_angle_deg=round(projected_angle_deg(a), 4) if spinning else None,
        reference_time_s=float(seq.t_s[0]),
        coarse_rate_deg_s=None if coarse is None else round(float(np.degrees(coarse)), 4),
    )  # fmt: skip
    quality = Quality(
        frames_used=len(seq.t_s), frames_with_target=n_found, line_tracks=obs.n_tracks,
        observations=len(obs.track), fit_rms_px=round(fit.rms_px, 4), revolutions_covered=round(revs, 4),
        step_deg_median=round(step, 4), nyquist_rate_deg_s=round(nyq, 4), model="rigid", flags=flags,
    )  # fmt: skip
    tracks = _tracks_out(seq, obs, fit.residuals_px) if seq.meta.options.return_tracks else None
    return SpinResult(spin=spin, quality=quality, frames=_frames_info(seq, feats, obs, fit.residuals_px),
                      tracks=tracks, timings_ms=_timings(clock))  # fmt: skip


def _cost_ratio(rival: RigidFit, fit: RigidFit) -> float:
    """The rival's cost over the fit's, both at the common Cauchy scale (1 = as good)."""
    cost = common_costs([fit, rival])
    return float(cost[1] / cost[0]) if cost[0] > 0 else float("inf")


def _static_result(
    seq: Sequence, feats: Features, obs: Observations, motion_px: float, flags: list[str], clock: dict[str, float]
) -> SpinResult:
    """Not spinning: the rate bound is what a motion of ``motion_px`` at the target's radius over the span means."""
    span = float(seq.t_s[-1] - seq.t_s[0])
    r_px = max(_radius_guess(seq, feats) * seq.meta.pinhole.focal_px, 1.0)
    bound = float(np.degrees(max(motion_px, STATIC_MOTION_PX) / r_px) / span)
    flags, n_found = _quality_common(seq, feats, obs, flags)
    spin = Spin(
        spinning=False, rate_deg_s=0.0, sigma_rate_deg_s=round(bound, 6), rate_rad_s=0.0, period_s=None,
        sigma_period_s=None, sense_about_los=None, axis_camera=None, sigma_axis_deg=None, axis_ambiguous=False,
        axis_candidates=[], axis_los_angle_deg=None, projected_axis_angle_deg=None,
        reference_time_s=float(seq.t_s[0]),
    )  # fmt: skip
    _, _, nyq = _sampling(seq, 0.0)
    quality = Quality(
        frames_used=len(seq.t_s), frames_with_target=n_found, line_tracks=obs.n_tracks, observations=len(obs.track),
        fit_rms_px=round(motion_px, 4), revolutions_covered=0.0, step_deg_median=0.0, nyquist_rate_deg_s=round(nyq, 4),
        model="static", flags=flags,
    )  # fmt: skip
    return SpinResult(
        spin=spin, quality=quality, frames=_frames_info(seq, feats, obs, None), timings_ms=_timings(clock)
    )
