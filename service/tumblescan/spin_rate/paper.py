"""The paper's method as written (Dong 2022, §3): the mean of the matched lines' end points in each
frame, then ``A·sin(B·t + C) + D`` fitted to u and to v by trust-region least squares; ω = |B|."""

from __future__ import annotations

import time

import numpy as np

from .._typing import FloatArray
from .errors import NotConvergedError, TooFewFeaturesError
from .result import FrameInfo, Quality, Spin, SpinResult


def paper_fit(seq, feats, tracks, obs, flags, clock, max_rate_deg_s: float) -> SpinResult:  # type: ignore[no-untyped-def]
    """The paper's pipeline on our tracks: lines matched through every frame with a target."""
    from scipy.optimize import least_squares

    found = [k for k, tg in enumerate(feats.targets) if tg.found]
    through = [tr for tr in tracks if all(k in tr.members for k in found)]
    warnings = []
    if not through:  # no line through the whole sequence: the mean of whatever is tracked in each frame
        through = tracks
        warnings.append("no line is matched through every frame: the mean point jumps as lines come and go")
    found = [k for k in found if any(k in tr.members for tr in through)]
    if len(found) < 6:
        raise TooFewFeaturesError(
            "frames: tracked lines in under 6 frames (the paper's sine fit needs them)", field="frames"
        )
    t = seq.t_s[found]
    ends = feats.segments
    pts = np.array([np.mean([ends[k].ends_px[tr.members[k]] for tr in through if k in tr.members], axis=(0, 1))
                    for k in found])  # fmt: skip
    span = float(t[-1] - t[0])
    omegas = np.arange(np.radians(0.5), np.radians(max_rate_deg_s), np.radians(5.0) / span)
    best = None
    for comp in (0, 1):
        y = pts[:, comp]
        # The frequency: best linear fit over a grid, then trust-region refinement of all four.
        costs = [_linear_cost(t, y, w)[0] for w in omegas]
        w0 = float(omegas[int(np.argmin(costs))])
        _, (s, c, d) = _linear_cost(t, y, w0)
        x0 = np.array([np.hypot(s, c), w0, np.arctan2(c, s), d])
        res = least_squares(lambda x, y=y: x[0] * np.sin(x[1] * t + x[2]) + x[3] - y, x0, method="trf")
        J = res.jac
        dof = max(len(t) - 4, 1)
        s2 = 2 * res.cost / dof
        try:
            cov = np.linalg.inv(J.T @ J) * s2
            sig = float(np.sqrt(cov[1, 1]))
        except np.linalg.LinAlgError:
            sig = float("inf")
        if best is None or sig / max(abs(res.x[1]), 1e-12) < best[1] / max(abs(best[0]), 1e-12):
            best = (float(res.x[1]), sig, float(np.sqrt(2 * res.cost / len(t))))
    assert best is not None
    if not np.isfinite(best[1]):
        raise NotConvergedError("frames: the sine fit did not converge (sigma not finite)", field="frames")
    rate = float(np.degrees(abs(best[0])))
    sigma = float(np.degrees(best[1]))
    dt_med = float(np.median(np.diff(seq.t_s)))
    spin = Spin(
        spinning=True, rate_deg_s=round(rate, 6), sigma_rate_deg_s=round(sigma, 6), rate_rad_s=round(abs(best[0]), 8),
        period_s=round(360 / rate, 6) if rate > 0 else None,
        sigma_period_s=round(360 / rate * sigma / rate, 6) if rate > 0 else None,
        sense_about_los=None, axis_camera=None, sigma_axis_deg=None, axis_ambiguous=False, axis_candidates=[],
        axis_los_angle_deg=None, projected_axis_angle_deg=None, reference_time_s=float(seq.t_s[0]),
    )  # fmt: skip
    quality = Quality(
        frames_used=len(seq.t_s), frames_with_target=len(found), line_tracks=len(through), observations=len(found),
        fit_rms_px=round(best[2], 4), revolutions_covered=round(rate * span / 360, 4),
        step_deg_median=round(rate * dt_med, 4),
        nyquist_rate_deg_s=round(180 / dt_med, 4), model="paper", flags=flags,
    )  # fmt: skip
    frames = [FrameInfo(index=k, t_s=float(seq.t_s[k]), target_found=tg.found, target_area_px=tg.area_px,
                        centroid_px=None if tg.centroid_px is None else [float(x) for x in tg.centroid_px],
                        lines=len(feats.segments[k]), tracked=len(through) if k in found else 0, rms_px=None)
              for k, tg in enumerate(feats.targets)]  # fmt: skip
    clock["fit"] = time.perf_counter()
    return SpinResult(method="paper", spin=spin, quality=quality, frames=frames, warnings=warnings,
                      timings_ms={"total": round(1000 * (clock["fit"] - clock["start"]), 1)})  # fmt: skip


def _linear_cost(t: FloatArray, y: FloatArray, w: float) -> tuple[float, FloatArray]:
    A = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)])
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    return float(np.sum((A @ coef - y) ** 2)), coef
