"""The result in words, shared by the CLI's summary and the HTML report: each value rounded to its
σ and printed with it; what the method or the geometry does not give is left out or "n/a" with
the reason, never Python's ``None`` (the CLI once printed "axis (camera): None, None deg" for the
paper's method, and the report "mirror twin None")."""

from __future__ import annotations

from typing import Any

from ..report.numbers import sigma_decimals
from .estimate import SENSE_MIN_FROM_PLANE_DEG


def with_sigma(value: float, sigma: float | None, unit: str) -> str:
    """``value ± sigma unit``, both rounded to the σ's second significant digit."""
    d = sigma_decimals(sigma, default=4, most=8)
    return f"{value:.{d}f} {unit}" if sigma is None else f"{value:.{d}f} ± {sigma:.{d}f} {unit}"


def vector_text(v: list[float]) -> str:
    return "[" + ", ".join(f"{x:.3f}" for x in v) + "]"


def summary_rows(result: dict[str, Any]) -> list[tuple[str, str]]:
    """(quantity, value) rows of a result document (``SpinResult.to_json()``)."""
    s, q = result["spin"], result["quality"]
    rows: list[tuple[str, str]] = []
    if q["model"] == "static":
        rows.append(("rate", f"not spinning (no motion above the noise: under {s['sigma_rate_deg_s']:.2g} deg/s)"))
    else:
        rate = with_sigma(s["rate_deg_s"], s["sigma_rate_deg_s"], "deg/s")
        rows.append(("rate", rate if s["spinning"] else f"{rate}: not spinning (under prior.min_rate_deg_s)"))
    if s["period_s"] is not None:
        rows.append(("period", with_sigma(s["period_s"], s["sigma_period_s"], "s")))
    rows += _axis_rows(result)
    rows.append(("tracks / observations", f"{q['line_tracks']} / {q['observations']}"))
    if q["fit_rms_px"] is not None:
        rows.append(("fit rms", f"{q['fit_rms_px']:.3g} px"))
    rows.append(("revolutions covered", f"{q['revolutions_covered']:.3g}"))
    rows.append(("flags", ", ".join(q["flags"]) or "none"))
    rows += [("warning", w) for w in result.get("warnings", [])]
    return rows


def _axis_rows(result: dict[str, Any]) -> list[tuple[str, str]]:
    """The axis, its angles, the sense, the mirror twin and rival rates: each only when given."""
    s = result["spin"]
    if s["axis_camera"] is None:
        if result.get("method") == "paper":
            return [("axis, sense", "n/a (the paper's sine fit gives the rate only)")]
        return [] if not s["spinning"] else [("axis, sense", "n/a")]
    sigma = s["sigma_axis_deg"]
    axis = vector_text(s["axis_camera"]) + (
        "" if sigma is None else f" ± {sigma:.{sigma_decimals(sigma, default=1, most=8)}f} deg"
    )
    rows = [("axis (camera)", axis)]
    if s["axis_los_angle_deg"] is not None:
        rows.append(("axis from the line of sight", f"{s['axis_los_angle_deg']:.1f} deg"))
    if s["projected_axis_angle_deg"] is not None:
        rows.append(("projected axis angle (from +x toward +y)", f"{s['projected_axis_angle_deg']:.1f} deg"))
    sense = s["sense_about_los"]
    if sense is None:
        why = f"the axis is within {SENSE_MIN_FROM_PLANE_DEG:g} deg of the image plane"
        rows.append(("sense about the line of sight", f"n/a ({why})"))
    else:
        way = "clockwise" if sense > 0 else "counter-clockwise"
        rows.append(("sense about the line of sight", f"{sense:+d} ({way} as displayed)"))
    for c in s["axis_candidates"]:
        if c["kind"] == "mirror":
            rows.append(("mirror twin (fits as well)", f"{vector_text(c['axis_camera'])} (cost ratio {c['cost']:.3g})"))
    rivals = [c["rate_deg_s"] for c in s["axis_candidates"] if c["kind"] == "rate" and c["rate_deg_s"] is not None]
    if rivals:
        d = sigma_decimals(s["sigma_rate_deg_s"], default=4, most=8)
        rows.append(("rival rates (not ruled out)", ", ".join(f"{r:.{d}f}" for r in rivals) + " deg/s"))
    return rows
