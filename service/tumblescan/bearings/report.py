"""The bearings report: a 3D view of the stations, the bearing rays and the located targets
with their 1σ error ellipsoids; a per-frame association table; unassociated detections marked."""

from __future__ import annotations

import html
from typing import Any

import numpy as np

from ..report import figure_html, page, table_html
from .epipolar import rays_job
from .inputs import BearingsInput

MAX_RAYS = 400
MAX_ELLIPSOIDS = 60
MAX_TABLE_ROWS = 300


def build_report(inp: BearingsInput, result: dict[str, Any], *, title: str) -> str:
    """The whole HTML page."""
    sections = [
        _summary(inp, result),
        _figure(inp, result),
        _close_up(inp, result),
        _tracks(result),
        _tables(inp, result),
    ]
    return page(title, sections)


def _summary(inp: BearingsInput, result: dict[str, Any]) -> str:
    s = result["summary"]
    un = ", ".join(f"{k}: {v}" for k, v in s["unassociated"].items())
    base = float(np.linalg.norm(inp.stations[1].p_job_m - inp.stations[0].p_job_m))
    rows = [
        ("method", s.get("method", "ml")),
        ("frame", result["frame"]),
        ("baseline", f"{base:.1f} m"),
        ("frames", str(len(result["frames"]))),
        ("targets (all frames)", str(s["targets"])),
        ("ambiguous", str(s["ambiguous"])),
        ("tracks (fitted, listed below)", str(s.get("tracks", 0))),
        ("tracks too short to fit (under 3 fixes)", str(s.get("short_tracks", 0))),
        ("unassociated detections", un),
        ("time", f"{result.get('timings_ms', {}).get('total', float('nan')):.0f} ms"),
    ]
    warnings = "".join(f"<p class='warn'>{html.escape(w)}</p>" for w in result.get("warnings", []))
    return "<h2>Summary</h2>" + table_html(["quantity", "value"], rows) + warnings


def _ellipsoid(p: np.ndarray, cov: np.ndarray, n: int = 12) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Surface of the 1σ ellipsoid of ``cov`` (3, 3) about ``p`` (3,)."""
    w, V = np.linalg.eigh(cov)
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, n), np.linspace(0, np.pi, n // 2 + 1))
    sphere = np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)], axis=-1)
    pts = p + sphere @ (V * np.sqrt(np.maximum(w, 0.0))).T
    return pts[..., 0], pts[..., 1], pts[..., 2]


def _add_ellipsoids(fig: Any, targets: list[dict[str, Any]], origin: np.ndarray) -> None:
    """The 1σ ellipsoids of (at most MAX_ELLIPSOIDS of) ``targets``, in green."""
    import plotly.graph_objects as go

    for t in targets[:MAX_ELLIPSOIDS]:
        x, y, z = _ellipsoid(np.asarray(t["position_m"]) - origin, np.asarray(t["cov_m2"]))
        fig.add_trace(
            go.Surface(
                x=x,
                y=y,
                z=z,
                opacity=0.3,
                showscale=False,
                colorscale=[[0, "green"], [1, "green"]],
                hoverinfo="skip",
                showlegend=False,
            )
        )


def _origin(inp: BearingsInput) -> np.ndarray:
    """The middle of the baseline: both 3D views' origin, so ECEF scenes stay readable."""
    return 0.5 * (inp.stations[0].p_job_m + inp.stations[1].p_job_m)


def _scene_layout(fig: Any, *, height: int) -> None:
    """True proportions, metres on every axis."""
    fig.update_layout(
        height=height,
        scene={"aspectmode": "data", "xaxis_title": "x (m)", "yaxis_title": "y (m)", "zaxis_title": "z (m)"},
        margin={"l": 0, "r": 0, "t": 30, "b": 0},
    )


def _figure(inp: BearingsInput, result: dict[str, Any]) -> str:
    import plotly.graph_objects as go

    origin = _origin(inp)
    fig = go.Figure()
    st = np.array([s.p_job_m - origin for s in inp.stations])
    fig.add_trace(
        go.Scatter3d(
            x=st[:, 0],
            y=st[:, 1],
            z=st[:, 2],
            mode="markers+text",
            text=[s.id for s in inp.stations],
            marker={"size": 6, "color": "black", "symbol": "diamond"},
            name="stations",
        )
    )
    fr_res = result["frames"][0]
    fr_in = inp.frames[0]
    targets = fr_res["targets"]
    p = np.array([t["position_m"] for t in targets]).reshape(-1, 3) - origin
    reach = float(np.max(np.linalg.norm(p, axis=1))) * 1.1 if len(p) else 1000.0
    used = {d for t in targets for d in t["detections"].values()}
    for s_i, (station, dets) in enumerate(zip(inp.stations, fr_in.detections, strict=True)):
        u = rays_job(dets, station)
        for kind, colour in (("associated", "rgba(40,120,200,0.35)"), ("unassociated", "rgba(220,60,40,0.8)")):
            sel = [j for j, d in enumerate(dets.ids) if (d in used) == (kind == "associated")][:MAX_RAYS]
            if not sel:
                continue
            xs, ys, zs = [], [], []
            for j in sel:
                a = station.p_job_m - origin
                b = a + reach * u[j]
                xs += [a[0], b[0], None]
                ys += [a[1], b[1], None]
                zs += [a[2], b[2], None]
            fig.add_trace(
                go.Scatter3d(
                    x=xs,
                    y=ys,
                    z=zs,
                    mode="lines",
                    line={"color": colour, "width": 2 if kind == "associated" else 4},
                    name=f"{station.id} rays ({kind})",
                    legendgroup=f"{s_i}{kind}",
                )
            )
    if len(p):
        ambiguous = np.array(["ambiguous" in t["flags"] for t in targets])
        fig.add_trace(
            go.Scatter3d(
                x=p[:, 0],
                y=p[:, 1],
                z=p[:, 2],
                mode="markers",
                marker={"size": 3, "color": np.where(ambiguous, "orange", "green")},
                text=[f"{t['id']} {t.get('track', '')} chi2={t['chi2']:.2f}" for t in targets],
                name="targets (frame 0)",
            )
        )
        _add_ellipsoids(fig, targets, origin)
    # Every frame's targets, faint, to show the tracks.
    allp = [np.array(t["position_m"]) - origin for fr in result["frames"][1:] for t in fr["targets"]]
    if allp:
        a = np.array(allp)
        fig.add_trace(
            go.Scatter3d(
                x=a[:, 0],
                y=a[:, 1],
                z=a[:, 2],
                mode="markers",
                marker={"size": 2, "color": "gray"},
                name="targets (later frames)",
            )
        )
    _scene_layout(fig, height=700)
    note = (
        "<p class='note'>Frame 0: stations, bearing rays (blue: associated, red: unassociated), located targets "
        "(green; orange if ambiguous) and their 1-sigma ellipsoids; later frames in gray. Coordinates are metres from "
        "the middle of the baseline, in the job frame's axes.</p>"
    )
    return "<h2>Geometry</h2>" + note + figure_html(fig, "bearings-3d")


def _close_up(inp: BearingsInput, result: dict[str, Any]) -> str:
    """The targets alone, scaled to them: each track's fixes over the frames joined in time order,
    untracked fixes as dots, and frame 0's 1σ ellipsoids (the geometry view above is scaled to the
    baseline, where a cluster of targets a kilometre away is a few pixels wide)."""
    import plotly.graph_objects as go

    origin = _origin(inp)
    by_track: dict[str, list[tuple[float, np.ndarray]]] = {}
    loose: list[np.ndarray] = []
    for fr in result["frames"]:
        for t in fr["targets"]:
            p = np.asarray(t["position_m"]) - origin
            if t.get("track"):
                by_track.setdefault(t["track"], []).append((fr["t"], p))
            else:
                loose.append(p)
    if not by_track and not loose:
        return ""
    fig = go.Figure()
    palette = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#17becf")
    for i, (track, fixes) in enumerate(sorted(by_track.items())[:MAX_ELLIPSOIDS]):
        a = np.array([p for _, p in sorted(fixes, key=lambda f: f[0])])
        fig.add_trace(
            go.Scatter3d(
                x=a[:, 0],
                y=a[:, 1],
                z=a[:, 2],
                mode="lines+markers",
                marker={"size": 3, "color": palette[i % len(palette)]},
                line={"color": palette[i % len(palette)], "width": 3},
                name=track,
            )
        )
    if loose:
        a = np.array(loose)
        fig.add_trace(
            go.Scatter3d(
                x=a[:, 0], y=a[:, 1], z=a[:, 2], mode="markers", marker={"size": 2, "color": "gray"}, name="untracked"
            )
        )
    _add_ellipsoids(fig, result["frames"][0]["targets"], origin)
    _scene_layout(fig, height=600)
    note = (
        "<p class='note'>The targets alone: each track's fixes joined in time order (one colour per track), "
        "untracked fixes in gray, frame 0's 1-sigma ellipsoids in green. Same coordinates as above.</p>"
    )
    return "<h2>Targets close up</h2>" + note + figure_html(fig, "bearings-close-up")


def _tracks(result: dict[str, Any]) -> str:
    tracks = result.get("tracks", [])
    if not tracks:
        return ""
    rows = []
    for tr in tracks[:MAX_TABLE_ROWS]:
        sigma = np.sqrt(np.abs(np.diag(np.asarray(tr["cov_m2"]))))
        speed = float(np.linalg.norm(tr["velocity_m_s"]))
        rows.append(
            [
                tr["id"],
                str(len(tr["frames"])),
                tr["model"],
                f"{tr['t_ref']:.3f}",
                ", ".join(f"{x:.2f}" for x in tr["position_m"]),
                ", ".join(f"{x:.2f}" for x in sigma),
                f"{speed:.2f}",
                f"{tr['chi2']:.1f} / {tr['dof']}",
            ]
        )
    note = (
        "<p class='note'>Each track's motion fitted through its fixes (weighted least squares); position and its "
        "1-sigma at t_ref. chi2 / dof near 1 means the fixes agree with the model and their covariances.</p>"
    )
    header = ["track", "fixes", "model", "t_ref (s)", "position (m)", "sigma (m)", "speed (m/s)", "chi2 / dof"]
    more = f"<p class='note'>({len(tracks) - MAX_TABLE_ROWS} more left out)</p>" if len(tracks) > MAX_TABLE_ROWS else ""
    return "<h2>Tracks</h2>" + note + table_html(header, rows) + more


def _tables(inp: BearingsInput, result: dict[str, Any]) -> str:
    parts = ["<h2>Association per frame</h2>"]
    rows_left = MAX_TABLE_ROWS
    s1, s2 = inp.stations[0].id, inp.stations[1].id
    for fr in result["frames"]:
        if rows_left <= 0:
            parts.append("<p class='note'>(further frames left out)</p>")
            break
        rows = []
        for t in fr["targets"][:rows_left]:
            rows.append(
                [
                    t["id"],
                    t.get("track", ""),
                    t["detections"][s1],
                    t["detections"][s2],
                    ", ".join(f"{x:.2f}" for x in t["position_m"]),
                    ", ".join(f"{x:.2f}" for x in t["sigma_m"]),
                    f"{t['chi2']:.2f}",
                    f"{t['parallax_deg']:.1f}",
                    ", ".join(t["flags"]),
                ]
            )
        rows_left -= len(rows)
        un = "; ".join(f"{k}: {', '.join(v) or 'none'}" for k, v in fr["unassociated"].items())
        parts.append(f"<h3>Frame {fr['index']} (t = {fr['t']:.3f} s)</h3>")
        parts.append(
            table_html(["target", "track", s1, s2, "position (m)", "sigma (m)", "chi2", "parallax (°)", "flags"], rows)
        )
        css = "warn" if any(fr["unassociated"].values()) else "note"
        parts.append(f"<p class='{css}'>Unassociated: {html.escape(un)}</p>")
    return "".join(parts)
