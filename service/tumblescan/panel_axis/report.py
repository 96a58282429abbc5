"""The HTML report: the image with the detected edges and the estimated axis drawn on it (and the
mirror twin when the view is ambiguous), then the numbers with their σ."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._typing import FloatArray
from ..errors import InputError
from ..imaging.camera import PinholeCamera
from ..io.json_text import parse_json
from ..report import image_html, page, table_html
from .meta import PanelAxisInput
from .segment import to_8bit

AXIS_BGR = (40, 40, 230)
MIRROR_BGR = (230, 160, 40)
LONG_BGR = (60, 200, 60)
SHORT_BGR = (200, 120, 220)


def load_truth(data: bytes | str, field: str = "truth") -> dict[str, Any]:
    """A simulation's truth.json as the report uses it: a JSON object whose ``axis_camera`` is
    3 finite numbers (a unit vector, camera frame); ``InputError`` naming the field otherwise."""
    doc = parse_json(data, field)
    if not isinstance(doc, dict):
        raise InputError(f"{field}: a JSON object (a simulation's truth.json) is expected", field=field)
    axis = doc.get("axis_camera")
    if not (
        isinstance(axis, list)
        and len(axis) == 3
        and all(isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x) for x in axis)
    ):
        raise InputError(f"{field}.axis_camera: 3 finite numbers expected (a simulation's truth.json)", field=field)
    crlb = doc.get("sigma_crlb_deg")
    if crlb is not None and not (isinstance(crlb, int | float) and not isinstance(crlb, bool)):
        raise InputError(f"{field}.sigma_crlb_deg: a number or null expected", field=field)
    return doc


def overlay_png(gray: FloatArray, meta: PanelAxisInput, result: dict[str, Any]) -> bytes:
    """The image (contrast stretched) with long edges green, short edges violet, wing corners, the
    axis red through the target and its mirror twin orange."""
    import cv2

    g8 = to_8bit(gray).astype(float)
    hi = max(float(np.percentile(g8, 99.9)), 1.0)
    img = cv2.cvtColor(np.clip(g8 * 255.0 / hi, 0, 255).astype(np.uint8), cv2.COLOR_GRAY2BGR)
    panel = result.get("panel", {})
    for key, colour in (("edges_px", LONG_BGR), ("short_edges_px", SHORT_BGR)):
        for x1, y1, x2, y2 in panel.get(key, []):
            cv2.line(img, _pt(x1, y1), _pt(x2, y2), colour, 1, cv2.LINE_AA)
    for x, y in panel.get("wing_corners_px") or []:
        cv2.circle(img, _pt(x, y), 4, MIRROR_BGR, 1, cv2.LINE_AA)
    edges = np.array(panel.get("edges_px") or [[0, 0, 0, 0]], dtype=float)
    centre = edges.reshape(-1, 2).mean(axis=0)
    half = 0.6 * float(np.ptp(edges.reshape(-1, 2), axis=0).max()) + 20
    cam = meta.pinhole
    axis = result.get("axis")
    candidates = result.get("candidates") or []
    if axis is not None:
        _draw_direction(img, cam, centre, np.array(axis["camera"]), half, AXIS_BGR, 2)
    for cand in candidates:
        if cand["kind"] == "mirror":
            _draw_direction(img, cam, centre + 3, np.array(cand["camera"]), half, MIRROR_BGR, 1)
    if axis is None:  # the in-image angle only
        a = np.radians(result["image_angle_deg"])
        d = np.array([np.cos(a), np.sin(a)])
        cv2.line(img, _pt(*(centre - half * d)), _pt(*(centre + half * d)), AXIS_BGR, 1, cv2.LINE_AA)
    ok, png = cv2.imencode(".png", img)
    return bytes(png) if ok else b""


def _draw_direction(
    img: np.ndarray,
    cam: PinholeCamera,
    c: FloatArray,
    d_cam: FloatArray,
    half: float,
    colour: tuple[int, int, int],
    width: int,
) -> None:
    """The image of the 3D line of direction ``d_cam`` through the point seen at ``c``: it runs from
    ``c`` toward the vanishing point ``K·d``."""
    import cv2

    v = cam.K @ d_cam
    t = v[:2] - c * v[2]
    n = float(np.linalg.norm(t))
    if n < 1e-12:
        return
    t = t / n
    cv2.line(img, _pt(*(c - half * t)), _pt(*(c + half * t)), colour, width, cv2.LINE_AA)


def _pt(x: float, y: float) -> tuple[int, int]:
    return round(x), round(y)


def build_report(
    gray: FloatArray, meta: PanelAxisInput, result: dict[str, Any], truth: dict[str, Any] | None = None
) -> str:
    """The whole page."""
    sections = [
        image_html(
            overlay_png(gray, meta, result),
            "green: edges along the axis; violet: edges across it; red: the estimated axis; "
            "orange: its mirror twin (weak perspective) and the wing corners used",
        )
    ]
    axis = result.get("axis")
    obs = result["observability"]
    rows: list[list[str]] = [
        ["method", result.get("method", "ours"), ""],
        # The paper's pipeline has no σ, hence no perspective SNR: its regime says nothing.
        ["regime", "n/a (paper method)", "no sigma, so weak perspective is not detected"]
        if result.get("method") == "paper"
        else ["regime", obs["regime"], f"perspective SNR {_f(obs.get('perspective_snr'), 3)}"],
        [
            "ambiguous",
            str(result["ambiguous"]),
            "mirror pair about the plane ⟂ the line of sight" if result["ambiguous"] else "",
        ],
        ["in-image angle (deg)", _f(result["image_angle_deg"]), f"sigma {_f(result.get('sigma_image_angle_deg'))}"],
    ]
    if axis is not None:
        rows += [
            ["axis, camera", _v(axis["camera"]), f"sigma {_f(axis.get('sigma_deg'))} deg"],
            ["axis, station ENU", _v(axis.get("station_enu")), ""],
            ["axis, ECEF", _v(axis.get("ecef")), ""],
            ["pitch (deg)", _f(axis.get("pitch_deg")), f"sigma {_f(axis.get('sigma_pitch_deg'))}"],
            ["yaw (deg)", _f(axis.get("yaw_deg")), f"sigma {_f(axis.get('sigma_yaw_deg'))}"],
            ["pitch, yaw ECEF (deg)", f"{_f(axis.get('pitch_ecef_deg'))}, {_f(axis.get('yaw_ecef_deg'))}", ""],
        ]
    else:
        rows.append(["axis", "not observable", "weak perspective without a panel-size prior: in-image angle only"])
    if obs.get("tilt_deg") is not None:
        rows.append(
            ["tilt out of the image plane (deg)", _f(obs["tilt_deg"]), f"sigma {_f(obs.get('sigma_tilt_deg'))}"]
        )
    panel = result["panel"]
    rows += [
        [
            "short axis, camera",
            _v((panel.get("short_axis") or {}).get("camera")),
            f"sigma {_f(panel.get('short_axis_sigma_deg'))} deg, fitted {panel.get('frame') or '-'}",
        ],
        [
            "orthogonality (deg)",
            _f(panel.get("orthogonality_deg")),
            "|90° - angle(axis, short axis)| as reported (0 when fitted ⟂ the axis)",
        ],
        [
            "Table 2 check (deg)",
            _f(panel.get("table2_orthogonality_deg")),
            "the paper's: the short edges' own fit against the axis, "
            f"sigma {_f(panel.get('table2_orthogonality_sigma_deg'))}",
        ],
        [
            "edges along / across",
            f"{panel.get('long_edges', 0)} / {panel.get('short_edges', 0)}",
            f"edge rms {_f(panel.get('edge_rms_px'), 3)} px",
        ],
        ["warnings", ", ".join(result.get("warnings", [])) or "none", ""],
    ]
    for c in result.get("candidates", []):
        rows.append(
            [
                f"candidate ({c['kind']})",
                _v(c.get("station_enu") or c["camera"]),
                f"cost {_f(c['cost'], 3)} px, sigma {_f(c.get('sigma_deg'))} deg",
            ]
        )
    if truth is not None and axis is not None:
        t = np.array(truth["axis_camera"])
        err = float(np.degrees(np.arccos(min(1.0, abs(float(np.dot(t, axis["camera"])))))))
        rows.append(
            [
                "error against the simulation's truth (deg)",
                _f(err),
                f"bound sigma_CRLB {_f(truth.get('sigma_crlb_deg'))}",
            ]
        )
    sections.append(table_html(["quantity", "value", "note"], rows))
    return page("Panel axis from one image", sections, with_plotly=False)


def _f(v: Any, digits: int = 4) -> str:
    return "n/a" if v is None else f"{float(v):.{digits}f}"


def _v(v: Any) -> str:
    return "n/a" if v is None else "[" + ", ".join(f"{x:.5f}" for x in v) + "]"
