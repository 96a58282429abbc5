"""Plain text of a motion estimate shared by the CLI and the HTML report: the fit in words,
and the comparison of an estimate with the simulation truth (CLI demo output)."""

from __future__ import annotations

from typing import Literal

import numpy as np

from ..report.html import sigmas_text
from ..target.motion import Motion
from .result import FitPublic, MotionResult
from .truth import errors_against


def fit_text(fit: FitPublic, unit: Literal["m", "mm"] = "m") -> str:
    """The fit in words, lengths in ``unit`` (``"m"`` or ``"mm"``). Frames: the RMS
    surfel-to-plane residual, the points used of the points given, the frames and the worst
    frame; tracks: the RMS residual over the observations, tracks, frames and outliers."""
    scale = {"m": 1.0, "mm": 1000.0}[unit]

    def length(v: float) -> str:
        return f"{v * scale:.3g} {unit}"

    if fit.source == "frames":
        worst = max(((v, i) for i, v in enumerate(fit.frame_rms_m or []) if v is not None), default=None)
        tail = f", worst frame {worst[1]} ({length(worst[0])})" if worst else ""
        used = "" if fit.points_used is None else f"{fit.points_used} of "
        return (
            f"rms {length(fit.rms_residual_m)} surfel-to-plane, {used}{fit.observations} points, "
            f"{fit.frames} frames{tail}"
        )
    return (
        f"rms {length(fit.rms_residual_m)} over {fit.observations} observations, {fit.tracks} tracks, "
        f"{fit.frames} frames, {fit.outliers} outliers"
    )


def comparison_table(result: MotionResult, truth: Motion) -> str:
    """Estimate +- 1 sigma next to the truth, at the estimate's reference time."""
    T = result.reference_time_s
    u = result.uncertainty
    err = errors_against(result, truth)
    rows = [("quantity", "estimate", "+- 1 sigma", "truth", "error")]
    rows.append(
        (
            "spin axis",
            _v(result.spin.axis),
            f"{u.spin_axis_deg:.2e} deg",
            _v(truth.spin_axis_at(T)),
            f"{err['spin_axis_deg']:.2e} deg",
        )
    )
    rows.append(
        (
            "spin rate (deg/s)",
            f"{result.spin.rate_deg_s:.5f}",
            f"{u.spin_rate_deg_s:.2e}",
            f"{np.degrees(truth.spin_rate_rad_s):.5f}",
            f"{err['spin_rate_deg_s']:+.2e}",
        )
    )
    if result.precession.axis is not None:
        rows.append(
            (
                "precession axis",
                _v(result.precession.axis),
                f"{u.precession_axis_deg:.2e} deg",
                _v(truth.precession_axis),
                f"{err['precession_axis_deg']:.2e} deg",
            )
        )
        rows.append(
            (
                "precession rate (deg/s)",
                f"{result.precession.rate_deg_s:.5f}",
                f"{u.precession_rate_deg_s:.2e}",
                f"{np.degrees(truth.precession_rate_rad_s):.5f}",
                f"{err['precession_rate_deg_s']:+.2e}",
            )
        )
    rows.append(
        (
            "centre (m)",
            _v(result.precession.center_m, 3),
            sigmas_text(u.center_m),
            _v(truth.center_m, 3),
            f"{err['center_m']:.2e} m",
        )
    )
    widths = [max(len(r[i]) for r in rows) for i in range(5)]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) for r in rows)


def _v(v: object, digits: int = 4) -> str:
    return "[" + ", ".join(f"{x:.{digits}f}" for x in np.asarray(v, dtype=float)) + "]"
