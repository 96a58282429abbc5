"""Self-contained HTML report of a motion estimate: summary with 1-sigma, a 3D view of the
rectified and distorted clouds with both axes and the precession cone, and residuals per
frame. Plotly's JavaScript is inlined from the installed package, so the file works offline.
"""

from __future__ import annotations

import html
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..geometry.rotations import tangent_basis
from ..io.ply import TimedCloud
from ..report import figure_html, page, sigmas_text, value_text
from ..target.motion import Motion
from .rectify import rectify
from .report_text import fit_text
from .result import MotionResult
from .tracks import Tracks
from .truth import errors_against

MAX_POINTS = 40_000


@dataclass
class ReportInputs:
    """What a report can show; everything but the result is optional."""

    result: MotionResult
    title: str = "Tumblescan motion estimate"
    tracks: Tracks | None = None
    distorted: TimedCloud | None = None
    rectified: TimedCloud | None = None
    truth: Motion | None = None
    job: dict[str, Any] | None = None


def frame_residuals(result: MotionResult, tracks: Tracks) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """RMS residual (m) of each frame: observations mapped to the reference time with the
    estimated motion, against their track's mean position there."""
    at_ref = rectify(tracks.xyz_m, tracks.t_s, result.motion(), to_time_s=result.reference_time_s)
    sums = np.zeros((tracks.n_tracks, 3))
    np.add.at(sums, tracks.track, at_ref)
    mean = sums / np.bincount(tracks.track, minlength=tracks.n_tracks)[:, None]
    err2 = np.sum((at_ref - mean[tracks.track]) ** 2, axis=1)
    frames = np.arange(tracks.n_frames)
    counts = np.bincount(tracks.frame, minlength=tracks.n_frames)
    rms = np.sqrt(np.bincount(tracks.frame, weights=err2, minlength=tracks.n_frames) / np.maximum(counts, 1))
    return frames, rms


def build_report(inputs: ReportInputs) -> str:
    """The report as one HTML document."""
    r = inputs.result
    parts = [
        _job_header(inputs.job),
        _summary(r, inputs.truth),
        "<h2>Rectified cloud, axes and precession cone</h2>",
        _figure_3d(inputs),
    ]
    if inputs.tracks is not None:
        frames, rms = frame_residuals(r, inputs.tracks)
        parts += ["<h2>Residuals per frame</h2>", _figure_residuals(frames, rms)]
    elif r.fit.frame_rms_m is not None:
        rms = np.array([np.nan if v is None else v for v in r.fit.frame_rms_m])
        parts += ["<h2>Surfel-to-plane residuals per frame (RMS)</h2>", _figure_residuals(np.arange(len(rms)), rms)]
    return page(inputs.title, parts)


def _job_header(job: dict[str, Any] | None) -> str:
    if not job:
        return ""
    cells = "".join(
        f"<th>{html.escape(k)}</th><td data-field='job.{k}'>{html.escape(str(job.get(k)))}</td>" for k in job
    )
    return f"<table class='job'><tr>{cells}</tr></table>"


def _summary(r: MotionResult, truth: Motion | None) -> str:
    u = r.uncertainty
    err = errors_against(r, truth) if truth is not None else {}
    t = truth.at_reference(r.reference_time_s) if truth is not None else None
    # The truth's nutation angle needs its precession: with a zero rate its axis is arbitrary.
    true_nutation = None
    if truth is not None and truth.precession_rate_rad_s != 0:
        true_nutation = truth.canonical().nutation_angle_deg()
        if r.nutation_angle_deg is not None:
            err["nutation_angle_deg"] = r.nutation_angle_deg - true_nutation
    rows = [
        _Row("spin axis", "spin.axis", r.spin.axis, f"{u.spin_axis_deg:.3g} deg", t and t.spin_axis, "spin_axis_deg",
             error_unit="deg"),
        _Row("spin rate (deg/s)", "spin.rate_deg_s", r.spin.rate_deg_s, f"{u.spin_rate_deg_s:.3g}",
             t and float(np.degrees(t.spin_rate_rad_s)), "spin_rate_deg_s"),
    ]  # fmt: skip
    if r.precession.axis is not None:
        rows += [
            _Row("precession axis", "precession.axis", r.precession.axis, f"{u.precession_axis_deg:.3g} deg",
                 t and t.precession_axis, "precession_axis_deg", error_unit="deg"),
            _Row("precession rate (deg/s)", "precession.rate_deg_s", r.precession.rate_deg_s,
                 f"{u.precession_rate_deg_s:.3g}", t and float(np.degrees(t.precession_rate_rad_s)),
                 "precession_rate_deg_s"),
            _Row("nutation angle (deg)", "nutation_angle_deg", r.nutation_angle_deg, "", true_nutation,
                 "nutation_angle_deg", no_error="the truth has no precession (rate 0), so no nutation angle"),
        ]  # fmt: skip
    rows.append(
        _Row(
            "centre (m)",
            "precession.center_m",
            r.precession.center_m,
            sigmas_text(u.center_m, 1000) + " mm",
            t and t.center_m,
            "center_m",
            error_scale=1000.0,
            error_unit="mm",
        )
    )
    head = (
        "<tr><th>quantity</th><th>estimate</th><th>1 sigma</th>"
        + ("<th>truth</th><th>error</th>" if t else "")
        + "</tr>"
    )
    body = "".join(row.html(err if t else None) for row in rows)
    val = r.validation
    verdict = f"<span class='{'ok' if val.passed else 'bad'}'>{'passed' if val.passed else 'FAILED'}</span>"
    facts = [
        ("model", "model", html.escape(r.model)),
        ("reference time (s)", "reference_time_s", f"{r.reference_time_s:.6f}"),
        ("validation", "validation.passed",
         f"{verdict} ({val.test}; frames {val.frames[0]} vs {val.frames[1]}; "
         f"distance {value_text(val.distance, 4)}, threshold {value_text(val.threshold, 4)})"),
        ("fit", "fit.rms_residual_m", html.escape(fit_text(r.fit, "mm"))),
        ("solver", "solver.path",
         f"{html.escape(r.solver.path)}; {r.solver.iterations} evaluations; {r.solver.attempts} attempt(s); "
         f"{r.solver.elapsed_s * 1000:.0f} ms"),
    ]  # fmt: skip
    fact_rows = "".join(f"<tr><th>{k}</th><td data-field='{f}'>{v}</td></tr>" for k, f, v in facts)
    warnings = "".join(f"<li class='warn'>{html.escape(w)}</li>" for w in r.warnings) or "<li class='ok'>none</li>"
    return f"""<h2>Summary</h2>
<table class="summary">{head}{body}</table>
<table class="facts">{fact_rows}</table>
<h3>Warnings</h3><ul data-field="warnings">{warnings}</ul>"""


@dataclass
class _Row:
    """One summary line: estimate, its 1 sigma, and (with a truth) the true value and error.

    The error is ``errors[error_key]`` times ``error_scale``, shown in ``error_unit`` (the unit
    of the sigma when the sigma shows one; none when the name carries it); without that
    error, a dash titled with ``no_error``, the reason."""

    name: str
    field: str
    value: Any
    sigma: str
    true: Any
    error_key: str
    error_scale: float = 1.0
    error_unit: str = ""
    no_error: str = ""

    def html(self, errors: dict[str, float] | None) -> str:
        value = value_text(self.value)
        cells = f"<th>{self.name}</th><td data-field='{self.field}'>{value}</td><td>{html.escape(self.sigma)}</td>"
        if errors is not None:
            cells += f"<td>{value_text(_plain(self.true))}</td>"
            if self.error_key in errors:
                error = f"{errors[self.error_key] * self.error_scale:.3g}"
                error += f" {self.error_unit}" if self.error_unit else ""
                cells += f"<td data-field='error.{self.field}'>{html.escape(error)}</td>"
            else:
                title = html.escape(self.no_error or "no error against this truth", quote=True)
                cells += f"<td data-field='error.{self.field}' title=\"{title}\">&ndash;</td>"
        return f"<tr>{cells}</tr>"


def _plain(v: Any) -> Any:
    if v is None:
        return None
    return [float(x) for x in v] if np.ndim(v) else float(v)


def _decimate(xyz: NDArray[np.float64], n: int) -> NDArray[np.float64]:
    if len(xyz) <= n:
        return xyz
    idx = np.random.default_rng(0).choice(len(xyz), n, replace=False)
    return xyz[np.sort(idx)]


def _figure_3d(inputs: ReportInputs) -> str:
    import plotly.graph_objects as go

    r = inputs.result
    fig = go.Figure()
    clouds: list[tuple[str, NDArray[np.float64], int]] = []
    if inputs.rectified is not None:
        clouds.append(("rectified", inputs.rectified.xyz_m, len(inputs.rectified)))
    elif inputs.tracks is not None:
        at_ref = rectify(inputs.tracks.xyz_m, inputs.tracks.t_s, r.motion(), to_time_s=r.reference_time_s)
        clouds.append(("rectified features", at_ref, len(at_ref)))
    if inputs.distorted is not None:
        clouds.append(("distorted input", inputs.distorted.xyz_m, len(inputs.distorted)))
    elif inputs.tracks is not None:
        clouds.append(("distorted features", inputs.tracks.xyz_m, len(inputs.tracks)))
    notes = []
    for i, (name, xyz, total) in enumerate(clouds):
        shown = _decimate(xyz, MAX_POINTS)
        notes.append(f"{name}: showing {len(shown):,} of {total:,} points")
        marker: dict[str, Any] = {"size": 1.5 if total > 1000 else 3, "color": shown[:, 2], "opacity": 0.8}
        marker["colorscale"] = "Viridis" if i == 0 else "Greys"
        visible = True if i == 0 else "legendonly"
        x, y, z = shown.T
        fig.add_trace(go.Scatter3d(x=x, y=y, z=z, mode="markers", name=name, visible=visible, marker=marker))
    center = np.asarray(r.precession.center_m)
    extent = float(np.max(np.ptp(clouds[0][1], axis=0))) if clouds else 10.0
    half = max(extent * 0.6, 1.0)
    for name, axis, color in (
        ("spin axis", r.spin.axis, "crimson"),
        ("precession axis", r.precession.axis, "royalblue"),
    ):
        if axis is None:
            continue
        a = np.asarray(axis)
        ends = np.stack([center - half * a, center + half * a])
        fig.add_trace(
            go.Scatter3d(
                x=ends[:, 0], y=ends[:, 1], z=ends[:, 2], mode="lines", name=name, line={"color": color, "width": 6}
            )
        )
    if r.precession.axis is not None and r.nutation_angle_deg is not None:
        fig.add_trace(_cone(center, np.asarray(r.precession.axis), np.radians(r.nutation_angle_deg), 0.5 * half))
    buttons = [
        {"label": label, "method": "restyle", "args": [{"visible": vis}, list(range(len(clouds)))]}
        for label, vis in (
            ("rectified", [True, "legendonly"]),
            ("distorted", ["legendonly", True]),
            ("both", [True, True]),
        )
    ]
    toggle = {"type": "buttons", "direction": "right", "x": 0.0, "y": 1.06, "buttons": buttons}
    fig.update_layout(
        height=640,
        margin={"l": 0, "r": 0, "t": 30, "b": 0},
        scene={"aspectmode": "data"},
        updatemenus=[toggle] if len(clouds) == 2 else [],
        legend={"itemsizing": "constant"},
    )
    div = figure_html(fig, "view3d")
    return f"<p class='note' data-field='decimation'>{html.escape('; '.join(notes))}</p>{div}"


def _cone(center: NDArray[np.float64], axis: NDArray[np.float64], half_angle: float, length: float) -> Any:
    """The precession cone swept by the spin axis, apex at the centre (both nappes)."""
    import plotly.graph_objects as go

    e1, e2 = tangent_basis(axis)
    phi = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    ring = np.cos(half_angle) * axis[None, :] + np.sin(half_angle) * (
        np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
    )
    pts = np.vstack([center[None, :], center + length * ring, center - length * ring])
    n = len(phi)
    i, j, k = [], [], []
    for base in (1, 1 + n):
        for m in range(n):
            i.append(0)
            j.append(base + m)
            k.append(base + (m + 1) % n)
    return go.Mesh3d(
        x=pts[:, 0],
        y=pts[:, 1],
        z=pts[:, 2],
        i=i,
        j=j,
        k=k,
        opacity=0.12,
        color="royalblue",
        name="precession cone",
        showlegend=True,
    )


def _figure_residuals(frames: NDArray[np.int64], rms: NDArray[np.float64]) -> str:
    import plotly.graph_objects as go

    fig = go.Figure(go.Bar(x=frames, y=rms * 1000, name="RMS residual"))
    fig.update_layout(
        height=300, margin={"l": 50, "r": 10, "t": 10, "b": 40}, xaxis_title="frame", yaxis_title="RMS residual (mm)"
    )
    return figure_html(fig, "residuals")
