"""The ``panel`` block of the result: the short axis (wing ends and sub-panel gaps), the panel
normal, the orthogonality of the reported frame and the paper's Table 2 check."""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray
from .axis import DirectionFit, angle_between_lines_deg
from .edges import Family
from .outputs import Frames
from .result import Panel


def panel_block(
    fit: DirectionFit,
    separate: DirectionFit,
    family: Family,
    short_family: Family | None,
    short_fit: DirectionFit | None,
    constrained: tuple[FloatArray, FloatArray] | None,
    frames: Frames,
    corners: FloatArray | None,
    *,
    weak: bool,
) -> Panel:
    """The panel block. With ``constrained`` (the short axis fitted ⟂ the axis, and its (3, 3)
    covariance) the short axis is orthogonal to the reported axis by construction; without it (no
    short edges, or short edges not orthogonal to the axis within σ) it is the short edges' own fit.
    Either way the paper's Table 2 check is between ``separate`` (the axis, fitted without the short
    edges) and ``short_fit`` (the short edges alone). In weak perspective (``weak``) every edge's
    plane holds the line of sight, so no 3D direction comes from them: the edges only."""
    rms = float(np.sqrt(np.mean([e.line.sigma_px**2 for e in family.edges])))
    panel = Panel(
        edge_rms_px=rms,
        edges_px=[e.line.endpoints_px.ravel().tolist() for e in family.edges],
        long_edges=len(family.edges),
        wing_corners_px=corners.tolist() if corners is not None else None,
    )
    if short_family is not None:
        panel.short_edges_px = [e.line.endpoints_px.ravel().tolist() for e in short_family.edges]
        panel.short_edges = len(short_family.edges)
    if short_family is None or short_fit is None or weak:
        return panel
    check, check_sigma = orthogonality_deg(separate, short_fit)
    panel.table2_orthogonality_deg, panel.table2_orthogonality_sigma_deg = check, check_sigma
    if constrained is not None:
        short, cov = constrained
        panel.frame = "constrained"
        panel.short_axis_sigma_deg = float(np.degrees(np.sqrt(max(np.linalg.eigvalsh(cov).max(), 0.0))))
        panel.orthogonality_deg = abs(90.0 - angle_between_lines_deg(fit.direction, short))
        panel.orthogonality_sigma_deg = 0.0
    else:
        short = short_fit.direction
        panel.frame = "separate"
        panel.short_axis_sigma_deg = float(np.degrees(short_fit.sigma_rad))
        panel.orthogonality_deg, panel.orthogonality_sigma_deg = orthogonality_deg(fit, short_fit)
    panel.short_axis = frames.direction(short)
    n = np.cross(fit.direction, short)
    panel.normal = frames.direction(n / np.linalg.norm(n))
    return panel


def orthogonality_deg(a: DirectionFit, b: DirectionFit) -> tuple[float, float]:
    """``|90° − angle(a, b)|`` (deg) and its σ from both fits' covariances (``a·b`` moves the angle
    by that much in radians)."""
    g1, g2 = a.basis @ b.direction, b.basis @ a.direction
    var = float(g1 @ a.cov_tangent_rad2 @ g1 + g2 @ b.cov_tangent_rad2 @ g2)
    return abs(90.0 - angle_between_lines_deg(a.direction, b.direction)), float(np.degrees(np.sqrt(max(var, 0.0))))
