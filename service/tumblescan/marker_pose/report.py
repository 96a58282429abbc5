"""The HTML report: trajectory in 3D with the markers, attitude angles and position over time with
3-sigma bands, residuals per marker."""

from __future__ import annotations

import html
from typing import Any

import numpy as np

from ..report import figure_html, page, table_html
from ..report.numbers import sigma_decimals
from .result import MarkerPoseResult


def build_report(result: MarkerPoseResult, title: str) -> str:
    import plotly.graph_objects as go

    from .geometry import matrix_from_quat_wxyz

    have = [p for p in result.poses if p.T_world_body is not None]
    t = np.array([p.t for p in have])
    pos = np.array([p.T_world_body.t_m for p in have]) if have else np.zeros((0, 3))  # type: ignore[union-attr]
    ypr = np.array([p.ypr_deg for p in have]) if have else np.zeros((0, 3))
    sig = np.array([np.sqrt(np.diag(p.cov)) if p.cov is not None else np.full(6, np.nan) for p in have])
    lay = np.array([m.xyz for m in result.layout.markers])
    fig3d = go.Figure(go.Scatter3d(x=pos[:, 0], y=pos[:, 1], z=pos[:, 2], mode="lines", name="body origin"))
    if have:
        last = have[-1]
        R = matrix_from_quat_wxyz(np.array(last.T_world_body.q_wxyz))  # type: ignore[union-attr]
        q = lay @ R.T + np.array(last.T_world_body.t_m)  # type: ignore[union-attr]
        fig3d.add_trace(
            go.Scatter3d(
                x=q[:, 0],
                y=q[:, 1],
                z=q[:, 2],
                mode="markers+text",
                name="markers (last frame)",
                text=[m.id for m in result.layout.markers],
            )
        )
    # Eye further out than plotly's default, which crops a flat trajectory's scene at the bottom.
    fig3d.update_layout(
        scene={"aspectmode": "data", "camera": {"eye": {"x": 1.8, "y": 1.8, "z": 1.2}}},
        height=550,
        margin={"l": 0, "r": 0, "t": 20, "b": 0},
    )
    sections = [
        table_html(
            ["level", "method", "body frame", "frames", "measured", "coverage", "residual RMS", "graph"],
            [
                [
                    result.level,
                    result.method,
                    result.body_frame,
                    len(result.poses),
                    sum(p.status == "measured" for p in result.poses),
                    f"{result.coverage:.3f}",
                    residual_text(result),
                    f"{result.graph.solver}, {result.graph.iterations} it, {result.graph.time_s:.2f} s",
                ]
            ],
        ),
        _detection_html(result),
        "<h2>Trajectory</h2>",
        figure_html(fig3d, "trajectory"),
    ]
    for name, values, s_idx, labels, unit, sigma_unit, sigma_scale in (
        ("Attitude (ZYX, launch frame)", ypr, (2, 1, 0), ("yaw", "pitch", "roll"), "deg", "deg", np.degrees(1.0)),
        ("Position (world)", pos, (3, 4, 5), ("x", "y", "z"), "m", "mm", 1000.0),
    ):
        sections += [
            f"<h2>{name}</h2>",
            figure_html(
                _series_figure(t, values, sig, s_idx, labels, unit, sigma_unit, sigma_scale), name.split()[0].lower()
            ),
        ]
    if result.residuals.per_tag_rms_px is not None:
        rows = [[k, f"{v:.3f}"] for k, v in result.residuals.per_tag_rms_px.items()]
        sections += ["<h2>Residuals per tag</h2>", table_html(["tag", "corner RMS [px]"], rows)]
    else:
        rows = [[k, f"{1000 * v:.2f}"] for k, v in result.residuals.per_marker_rms_m.items()]
        sections += ["<h2>Residuals per marker</h2>", table_html(["marker", "RMS [mm]"], rows)]
    sections.append(f"<p>{len(result.residuals.rejected)} observations rejected.</p>")
    if result.warnings:
        sections.append("<h2>Warnings</h2>" + "".join(f"<p class='warn'>{html.escape(w)}</p>" for w in result.warnings))
    return page(title, sections)


def residual_text(result: MarkerPoseResult) -> str:
    """The overall residual with its unit: mm for markers, px for tag corners."""
    if result.residuals.rms_m is not None:
        return f"{1000 * result.residuals.rms_m:.2f} mm"
    if result.residuals.rms_px is not None:
        return f"{result.residuals.rms_px:.3f} px"
    return "-"


def pose_text(result: MarkerPoseResult) -> list[str]:
    """The estimate in a line or two for the CLI's summary: the last measured frame's pose with its
    1-sigma (position per world axis; attitude as yaw, pitch, roll from the launch frame, its sigma
    the per-axis RMS of the rotation's), then the median 1-sigma over every measured frame."""
    measured = [p for p in result.poses if p.status == "measured" and p.T_world_body is not None]
    if not measured:
        return []
    last = measured[-1]
    assert last.T_world_body is not None and last.ypr_deg is not None
    position = ", ".join(f"{v:.4f}" for v in last.T_world_body.t_m)
    attitude = ", ".join(f"{v:.2f}" for v in last.ypr_deg)
    text = f"last measured frame {last.frame} (t {last.t:.3f} s): position [{position}] m"
    if last.cov is not None:
        sigma = np.sqrt(np.diag(np.array(last.cov)))
        text += " +- [" + ", ".join(_two_digits(1000 * v) for v in sigma[3:]) + "] mm"
    text += f", yaw/pitch/roll from launch [{attitude}] deg"
    if last.cov is not None:
        text += f" +- {_two_digits(float(np.degrees(np.sqrt(np.trace(np.array(last.cov)[:3, :3]) / 3))))} deg"
    lines = [text + (" (1 sigma)" if last.cov is not None else " (no covariance: marginals off)")]
    covs = np.array([p.cov for p in measured if p.cov is not None])
    if len(covs):
        rot = np.degrees(np.median(np.sqrt(np.trace(covs[:, :3, :3], axis1=1, axis2=2) / 3)))
        pos = 1000 * np.median(np.sqrt(np.trace(covs[:, 3:, 3:], axis1=1, axis2=2) / 3))
        lines.append(
            f"median 1-sigma over {len(covs)} measured frames: {_two_digits(float(rot))} deg attitude, "
            f"{_two_digits(float(pos))} mm position (per axis)"
            + (" (method 'paper': relative to its first frame, not comparable)" if result.method == "paper" else "")
        )
    return lines


def _two_digits(x: float) -> str:
    """Two significant digits without an exponent (a sigma: 0.021, 1.3, 17, 240)."""
    if not np.isfinite(x) or x <= 0:
        return f"{x:g}"
    return f"{x:.{sigma_decimals(x)}f}"


def _detection_html(result: MarkerPoseResult) -> str:
    """Level C: what the detector found; levels B and C: the corner sigma used."""
    parts = []
    d = result.detection
    if d is not None:
        parts.append(
            f"<p>Tags detected by {d.detector} in {d.images} images: {d.detections} detections, "
            f"{d.known_tags} of the layout's tags, in {d.time_s:.1f} s.</p>"
        )
    if result.pixel_sigma_px:
        sig = ", ".join(f"{k} {v:.3f}" for k, v in result.pixel_sigma_px.items())
        parts.append(f"<p>Corner sigma per camera [px]: {sig}.</p>")
    return "".join(parts)


PALETTE = ("#1f77b4", "#d62728", "#2ca02c")


def _series_figure(
    t: np.ndarray,
    values: np.ndarray,
    sig: np.ndarray,
    s_idx: tuple[int, int, int],
    labels: tuple[str, str, str],
    unit: str,
    sigma_unit: str,
    sigma_scale: float,
) -> Any:
    """Three components over time (top) and their 3σ (bottom, in ``sigma_unit``), one colour per
    component: a 3σ band drawn around a curve that spans tens of degrees would be thinner than the
    line, so the uncertainty gets its own axis."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    fig = make_subplots(rows=2, cols=1, shared_xaxes=True, row_heights=[0.65, 0.35], vertical_spacing=0.06)
    for j, label in enumerate(labels):
        colour = PALETTE[j]
        fig.add_trace(
            go.Scatter(x=t, y=values[:, j], mode="lines", line={"color": colour}, name=f"{label} [{unit}]"),
            row=1,
            col=1,
        )
        three_sigma = 3 * sig[:, s_idx[j]] * sigma_scale if len(sig) else np.zeros(0)
        fig.add_trace(
            go.Scatter(
                x=t,
                y=three_sigma,
                mode="lines",
                line={"color": colour, "dash": "dot"},
                name=f"{label} 3-sigma [{sigma_unit}]",
            ),
            row=2,
            col=1,
        )
    fig.update_yaxes(title_text=unit, row=1, col=1)
    fig.update_yaxes(title_text=f"3-sigma [{sigma_unit}]", rangemode="tozero", row=2, col=1)
    fig.update_xaxes(title_text="t [s]", row=2, col=1)
    fig.update_layout(height=450, margin={"t": 20})
    return fig
