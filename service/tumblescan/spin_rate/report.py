"""The HTML report: a frame strip with the tracked lines drawn, the fitted rotation angle against
time with residuals, the spin axis drawn on the first frame, and the numbers with their σ."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..report import figure_html, image_html, page, table_html
from .estimate import Sequence
from .text import summary_rows

LINE_BGR = (60, 200, 60)
AXIS_BGR = (40, 40, 230)
MIRROR_BGR = (230, 160, 40)


def _frame_bgr(gray: np.ndarray) -> np.ndarray:
    import cv2

    lo, hi = float(np.percentile(gray, 1)), float(np.percentile(gray, 99.9))
    # A square-root stretch: dark solar panels beside a sunlit bus stay visible.
    g = np.sqrt(np.clip((gray - lo) / max(hi - lo, 1e-9), 0.0, 1.0))
    return np.asarray(cv2.cvtColor((255.0 * g).astype(np.uint8), cv2.COLOR_GRAY2BGR))


def _target_box(grays: list[np.ndarray]) -> tuple[int, int, int, int]:
    """A square (x0, y0, x1, y1) holding the target in every frame given, with a margin: the
    strip's tiles show the target, not the empty sky around it."""
    h, w = grays[0].shape
    ys, xs = [], []
    for gray in grays:
        lo, hi = float(np.percentile(gray, 50)), float(np.percentile(gray, 99.9))
        yy, xx = np.nonzero(gray > lo + 0.05 * (hi - lo))
        if len(xx) > 20:  # a few hot pixels or stars are not a target
            ys += [float(np.percentile(yy, 0.5)), float(np.percentile(yy, 99.5))]
            xs += [float(np.percentile(xx, 0.5)), float(np.percentile(xx, 99.5))]
    if not xs:
        return 0, 0, w, h
    cx, cy = (min(xs) + max(xs)) / 2, (min(ys) + max(ys)) / 2
    half = min(max(max(xs) - min(xs), max(ys) - min(ys), 32.0) * 0.6, max(w, h) / 2)
    x0, y0 = int(max(0, min(cx - half, w - 2 * half))), int(max(0, min(cy - half, h - 2 * half)))
    return x0, y0, int(min(w, x0 + 2 * half)), int(min(h, y0 + 2 * half))


def strip_png(seq: Sequence, result: dict[str, Any], n: int = 6) -> bytes:
    """Up to ``n`` frames side by side, cropped to the target and scaled to 200 px, with their
    tracked lines in green."""
    import cv2

    tracks = result.get("tracks") or []
    idx = np.unique(np.linspace(0, len(seq.grays) - 1, n).round().astype(int))
    bx0, by0, bx1, by1 = _target_box([seq.grays[k] for k in idx])
    tiles = []
    for k in idx:
        img = _frame_bgr(seq.grays[k])
        for ob in tracks:
            if ob["frame"] == k:
                (x1, y1), (x2, y2) = ob["ends_px"]
                cv2.line(img, (round(x1), round(y1)), (round(x2), round(y2)), LINE_BGR, 1, cv2.LINE_AA)
        img = img[by0:by1, bx0:bx1]
        s = 200.0 / img.shape[1]
        tiles.append(cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA))
    return bytes(cv2.imencode(".png", np.hstack(tiles))[1].tobytes())


def axis_png(seq: Sequence, result: dict[str, Any]) -> bytes:
    """The first frame with the spin axis (red, arrow along the spin vector) and its mirror twin (orange)."""
    import cv2

    img = _frame_bgr(seq.grays[0])
    spin = result["spin"]
    frame0 = result["frames"][0]
    centre = frame0.get("centroid_px") or [img.shape[1] / 2, img.shape[0] / 2]
    half = 0.3 * img.shape[1]
    axes = [(spin.get("axis_camera"), AXIS_BGR)] + [
        (c["axis_camera"], MIRROR_BGR) for c in spin.get("axis_candidates", []) if c.get("kind") == "mirror"
    ]
    for axis, colour in axes:
        if axis is None:
            continue
        a = np.asarray(axis, dtype=float)
        d = a[:2] / max(float(np.linalg.norm(a[:2])), 1e-9) * half * float(np.linalg.norm(a[:2]))
        p0 = (int(centre[0] - d[0]), int(centre[1] - d[1]))
        p1 = (int(centre[0] + d[0]), int(centre[1] + d[1]))
        cv2.arrowedLine(img, p0, p1, colour, 2, cv2.LINE_AA, tipLength=0.08)
    return bytes(cv2.imencode(".png", img)[1].tobytes())


def angle_figure(seq: Sequence, result: dict[str, Any]) -> str:
    """The fitted rotation angle ω (t - t_ref) at each frame, and each frame's residual rms."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    t = np.asarray(seq.t_s)
    spin = result["spin"]
    fig = make_subplots(rows=2, cols=1, shared_xaxes=True, subplot_titles=("rotation angle (deg)", "residual rms (px)"))
    ang = spin["rate_deg_s"] * (t - spin["reference_time_s"])
    fig.add_trace(go.Scatter(x=t, y=ang, mode="lines+markers", name="fitted angle"), row=1, col=1)
    rms = [f.get("rms_px") for f in result["frames"]]
    fig.add_trace(go.Scatter(x=t, y=rms, mode="markers", name="residual rms"), row=2, col=1)
    fig.update_xaxes(title_text="t (s)", row=2, col=1)
    fig.update_layout(height=500, showlegend=False)
    return figure_html(fig, "angle")


def build_report(seq: Sequence, result: dict[str, Any]) -> str:
    """The page: the numbers (as the CLI prints them), the frame strip, the axis and the fitted angle."""
    sections = [
        "<h2>Spin</h2>" + table_html(["quantity", "value"], summary_rows(result)),
        "<h2>Frames and tracked lines</h2>" + image_html(strip_png(seq, result), "tracked lines (green)"),
        "<h2>Spin axis on the first frame</h2>"
        + image_html(axis_png(seq, result), "axis red (arrow: spin vector), mirror twin orange"),
        "<h2>Fitted angle and residuals</h2>" + angle_figure(seq, result),
    ]
    return page("spin-from-images", sections)
