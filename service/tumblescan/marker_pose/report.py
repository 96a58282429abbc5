"""The HTML report: trajectory in 3D with the markers, attitude angles and position over time with
3-sigma bands, residuals per marker."""

from __future__ import annotations

import numpy as np

from ..report import figure_html, page, table_html
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
    fig3d.update_layout(scene={"aspectmode": "data"}, height=500)
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
    for name, values, s_idx, unit, scale in (
        ("Attitude (ZYX, launch frame)", ypr, (2, 1, 0), "deg", None),
        ("Position (world)", pos, (3, 4, 5), "m", 1.0),
    ):
        fig = go.Figure()
        for j, label in enumerate(("yaw", "pitch", "roll") if unit == "deg" else ("x", "y", "z")):
            s = 3 * sig[:, s_idx[j]] * (np.degrees(1.0) if scale is None else scale) if len(sig) else np.zeros(0)
            fig.add_trace(go.Scatter(x=t, y=values[:, j] + s, mode="lines", line={"width": 0}, showlegend=False))
            fig.add_trace(
                go.Scatter(
                    x=t,
                    y=values[:, j] - s,
                    mode="lines",
                    line={"width": 0},
                    fill="tonexty",
                    name=f"{label} 3-sigma",
                    opacity=0.3,
                )
            )
            fig.add_trace(go.Scatter(x=t, y=values[:, j], mode="lines", name=f"{label} [{unit}]"))
        fig.update_layout(xaxis_title="t [s]", height=350)
        sections += [f"<h2>{name}</h2>", figure_html(fig, name.split()[0].lower())]
    if result.residuals.per_tag_rms_px is not None:
        rows = [[k, f"{v:.3f}"] for k, v in result.residuals.per_tag_rms_px.items()]
        sections += ["<h2>Residuals per tag</h2>", table_html(["tag", "corner RMS [px]"], rows)]
    else:
        rows = [[k, f"{1000 * v:.2f}"] for k, v in result.residuals.per_marker_rms_m.items()]
        sections += ["<h2>Residuals per marker</h2>", table_html(["marker", "RMS [mm]"], rows)]
    sections.append(f"<p>{len(result.residuals.rejected)} observations rejected.</p>")
    if result.warnings:
        sections.append("<h2>Warnings</h2>" + "".join(f"<p class='warn'>{w}</p>" for w in result.warnings))
    return page(title, sections)


def residual_text(result: MarkerPoseResult) -> str:
    """The overall residual with its unit: mm for markers, px for tag corners."""
    if result.residuals.rms_m is not None:
        return f"{1000 * result.residuals.rms_m:.2f} mm"
    if result.residuals.rms_px is not None:
        return f"{result.residuals.rms_px:.3f} px"
    return "-"


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
