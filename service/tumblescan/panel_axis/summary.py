"""The CLI's human-readable result: every value with its σ, rounded to what the σ supports, and
what a method does not give said to be absent ("n/a (paper method)"), never printed as ``None``."""

from __future__ import annotations

import math

from ..report.numbers import sigma_decimals
from .result import Axis, Candidate, PanelAxisResult

PAPER = "paper method"  # the only one without σ
PAPER_NA = f"n/a ({PAPER})"


def with_sigma(value: float, sigma: float | None, unit: str = "deg", *, why: str = PAPER) -> str:
    """``value ± sigma unit``, both to the decimal of σ's second significant digit (0.16, 1.7, 12),
    or ``value unit (sigma n/a: <why>)`` with 3 decimals when there is no σ."""
    if sigma is None or not math.isfinite(sigma):
        return f"{value:.3f} {unit} (sigma n/a: {why})"
    d = decimals(sigma)
    return f"{value:.{d}f} ± {sigma:.{d}f} {unit}"


def decimals(sigma: float) -> int:
    """Decimals that show σ to 2 significant digits (0 to 6; 3 for a σ of 0)."""
    return sigma_decimals(sigma, default=3)


def sigma_text(sigma: float | None, unit: str = "deg", *, why: str = PAPER) -> str:
    if sigma is None or not math.isfinite(sigma):
        return f"sigma n/a ({why})"
    return f"sigma {sigma:.{decimals(sigma)}f} {unit}"


def _vec(v: list[float]) -> str:
    return "[" + ", ".join(f"{x:.6f}" for x in v) + "]"


def _direction_lines(name: str, axis: Axis | Candidate, extra: str = "") -> list[str]:
    lines = [f"{name} (camera): {_vec(axis.camera)}, {sigma_text(axis.sigma_deg)}{extra}"]
    if axis.station_enu is not None:
        lines.append(f"{name} (station ENU): {_vec(axis.station_enu)}")
    if axis.pitch_deg is not None and axis.yaw_deg is not None:
        if axis.sigma_pitch_deg is None and axis.sigma_yaw_deg is None:  # one note for both
            lines.append(f"{name} pitch {axis.pitch_deg:.3f} deg, yaw {axis.yaw_deg:.3f} deg (sigma n/a: {PAPER})")
        else:
            pitch = with_sigma(axis.pitch_deg, axis.sigma_pitch_deg)
            yaw = with_sigma(axis.yaw_deg, axis.sigma_yaw_deg)
            lines.append(f"{name} pitch {pitch}, yaw {yaw}")
    return lines


def summary_lines(result: PanelAxisResult) -> list[str]:
    """The lines ``tumblescan panel-axis estimate`` prints without ``--json``."""
    paper = result.method == "paper"
    obs = result.observability
    lines = []
    if paper:
        # The paper's pipeline has no σ, hence no perspective SNR: it cannot tell weak perspective,
        # and its result's regime says nothing.
        lines.append(f"regime: n/a ({PAPER}: no sigma, so weak perspective is not detected)")
    else:
        regime = obs.regime.replace("_", " ")
        snr = f" (perspective SNR {obs.perspective_snr:.3g})" if obs.perspective_snr is not None else ""
        lines.append(f"regime: {regime}{snr}")
    lines.append(f"in-image angle: {with_sigma(result.image_angle_deg, result.sigma_image_angle_deg)}")
    if obs.tilt_deg is not None:
        lines.append(f"tilt out of the image plane: {with_sigma(obs.tilt_deg, obs.sigma_tilt_deg)}")
    mirror = next((c for c in result.candidates if c.kind == "mirror"), None)
    primary = next((c for c in result.candidates if c.kind == "primary"), None)
    if result.ambiguous:
        if result.candidates:
            lines.append(
                "ambiguous: the axis and its mirror twin (about the plane ⟂ the line of sight) fit equally "
                "well (weak perspective); one image cannot tell which is the panel's"
            )
        else:
            lines.append("ambiguous: weak perspective; the axis's tilt out of the image plane is not observable")
    axis = result.axis
    if axis is None:
        if "wing_corners_not_found" in result.warnings:
            lines.append("axis: not observable (weak perspective, and no wing's four corners fit the panel prior)")
        else:
            lines.append("axis: not observable (weak perspective without a panel-size prior)")
    else:
        cost = f", reprojection cost {primary.cost:.2f} px" if primary is not None else ""
        lines += _direction_lines("axis", axis, cost)
    if mirror is not None:
        lines += _direction_lines("mirror twin", mirror, f", reprojection cost {mirror.cost:.2f} px")
    elif result.ambiguous and axis is not None:
        lines.append("mirror twin: not found (IPPE returned one pose)")
    lines += [f"warning: {w}" for w in result.warnings]
    return lines
