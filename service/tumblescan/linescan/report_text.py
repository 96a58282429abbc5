"""Plain-text comparison of an estimate with the simulation truth (CLI demo output)."""

from __future__ import annotations

import numpy as np

from ..report.html import sigmas_text
from ..target.motion import Motion
from .result import MotionResult
from .truth import errors_against


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
