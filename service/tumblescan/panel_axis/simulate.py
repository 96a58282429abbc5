"""Seeded simulated views of a box-bus satellite with two wings, with the truth beside them.

Regimes: ``near`` (1024x768, horizontal field 12-30°, range 42-111 m, 8-bit, PSF 0.6 px) and
``ground`` (a telescope at 400-900 km whose focal length makes the target span 35-70 % of the
image, 16-bit, PSF 1.8 px): weak perspective. Cases: ``normal`` (attitude uniform, rejecting axes
under 25° from the line of sight, panel normals over 72° from it and an unlit visible face),
``edge-on`` (the panel plane contains the line of sight), ``end-on`` (axis 3° from the line of
sight), ``blank`` (sky and stars only) and ``broken-meta`` (a normal view with one bad field).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from .._typing import FloatArray
from ..imaging.camera import PinholeCamera, camera_from_fov
from ..imaging.image_io import write_image
from ..imaging.render import render
from ..imaging.sensor import SensorModel, expose
from .axis import direction_bound, plane_obs
from .frames import R_cam_from_enu, R_ecef_from_enu, canonical, pitch_yaw_deg
from .meta import INPUT_SCHEMA
from .spacecraft import Spacecraft, random_spacecraft

Regime = Literal["near", "ground"]
Case = Literal["normal", "edge-on", "end-on", "blank", "broken-meta"]
STATION = {"lat_deg": 34.27, "lon_deg": 108.95, "height_m": 400.0}
CRLB_POINT_SIGMA_PX = 0.05
MIN_AXIS_TO_LOS_DEG = 25.0
MAX_NORMAL_TO_LOS_DEG = 72.0
MIN_SUN_COS = 0.3

# One bad field per broken-meta variant: (field, expected error code, how to break the dict).
BROKEN_META: list[tuple[str, str]] = [
    ("schema", "unknown schema"),
    ("camera.fx_px", "fx <= 0"),
    ("camera.cx_px", "cx outside the image"),
    ("camera.width_px", "width not the image's"),
    ("pointing.elevation_deg", "elevation over 90"),
    ("camera.fy_px", "NaN"),
    ("pointing.R_cam_from_ref", "not a rotation"),
    ("prior.panel_length_m", "prior <= 0"),
    ("camera.distortion", "wrong length"),
]


@dataclass
class SimulatedView:
    """The image (uint8/uint16), meta.json (dict) and truth.json (dict) of one view."""

    image: np.ndarray
    meta: dict[str, Any]
    truth: dict[str, Any]


def simulate_view(
    seed: int,
    regime: Regime = "near",
    *,
    noise: bool = True,
    case: Case = "normal",
    width_px: int = 1024,
    height_px: int = 768,
    bits: int | None = None,
    image_name: str = "image.png",
) -> SimulatedView:
    """Render one seeded view (see the module docstring)."""
    return simulate_views(
        seed,
        regime,
        noises=(noise,),
        case=case,
        width_px=width_px,
        height_px=height_px,
        bits=bits,
        image_name=image_name,
    )[0]


def simulate_views(
    seed: int,
    regime: Regime = "near",
    *,
    noises: tuple[bool, ...] = (False, True),
    case: Case = "normal",
    width_px: int = 1024,
    height_px: int = 768,
    bits: int | None = None,
    image_name: str = "image.png",
) -> list[SimulatedView]:
    """The same scene exposed once per entry of ``noises`` (one render: clean and noisy twins)."""
    rng = np.random.default_rng(seed)
    craft = random_spacecraft(rng)
    az, el = float(rng.uniform(0, 360)), float(rng.uniform(25, 85))
    R_cam_enu = R_cam_from_enu(az, el)
    camera, t_cam_m, R, sun = _geometry(rng, craft, regime, case, width_px, height_px)
    # Render once (a blank view is sky and stars only), then expose per noise setting.
    if case == "blank":
        radiance = np.zeros((height_px, width_px))
    else:
        radiance = render(craft.mesh(), camera, R, t_cam_m, sun).radiance
    views = []
    for k, noise in enumerate(noises):
        image = expose(radiance, _sensor(regime, noise, bits), np.random.default_rng([seed, k]))
        meta = _meta(camera, az, el, float(np.linalg.norm(t_cam_m)), craft, image_name)
        truth = _truth(camera, craft, R, t_cam_m, sun, R_cam_enu, regime, case, seed, noise)
        if case == "broken-meta":
            field = BROKEN_META[seed % len(BROKEN_META)][0]
            _break(meta, field, R_cam_enu)
            truth["expected_error"] = {"code": "invalid_input", "field": field}
        views.append(SimulatedView(image, meta, truth))
    return views


def write_view(out: Path, view: SimulatedView) -> dict[str, Path]:
    """Write image, meta.json and truth.json into ``out``; return their paths."""
    out.mkdir(parents=True, exist_ok=True)
    paths = {"image": out / view.meta.get("image", "image.png"), "meta": out / "meta.json", "truth": out / "truth.json"}
    write_image(paths["image"], view.image)
    paths["meta"].write_text(json.dumps(view.meta, indent=2, allow_nan=True))
    paths["truth"].write_text(json.dumps(view.truth, indent=2))
    return paths


def _geometry(
    rng: np.random.Generator, craft: Spacecraft, regime: Regime, case: Case, W: int, H: int
) -> tuple[PinholeCamera, FloatArray, FloatArray, FloatArray]:
    """Camera, target position, attitude and sun (camera frame) meeting the case's constraints."""
    span_m = 2 * (craft.wing_root_m + craft.panel_length_m)
    verts = craft.mesh().vertices_m
    for _ in range(10_000):
        if regime == "near":
            camera = camera_from_fov(W, H, float(rng.uniform(12, 30)))
            range_m = float(rng.uniform(42, 111))
        else:
            range_m = float(rng.uniform(400e3, 900e3))
            f = float(rng.uniform(0.35, 0.7)) * W * range_m / span_m
            camera = PinholeCamera(W, H, f, f, (W - 1) / 2, (H - 1) / 2)
        uv0 = np.array([camera.cx_px, camera.cy_px]) + rng.uniform(-0.08, 0.08, 2) * [W, H]
        los = camera.rays(uv0)[0]
        t_cam_m = los * range_m
        R, sun = _attitude(rng, craft, los, case)
        if R is None or sun is None:
            continue
        uv = camera.project(verts @ R.T + t_cam_m)
        if not camera.contains(uv, margin_px=8):
            continue
        if case != "end-on" and np.ptp(uv[:, 0]) ** 2 + np.ptp(uv[:, 1]) ** 2 < (0.3 * W) ** 2:
            continue  # too small for this camera
        return camera, t_cam_m, R, sun
    raise RuntimeError("no view met the constraints")


def _attitude(
    rng: np.random.Generator, craft: Spacecraft, los: FloatArray, case: Case
) -> tuple[FloatArray | None, FloatArray | None]:
    """Body-to-camera rotation and sun direction for the case, or (None, None) when rejected."""
    from scipy.spatial.transform import Rotation

    n_body = craft.panel_normal_body
    y_body = np.array([0.0, 1.0, 0.0])
    if case == "edge-on":
        n_cam = _unit(np.cross(los, rng.normal(size=3)))  # panel normal ⟂ line of sight
        a = np.radians(rng.uniform(40, 90))
        e2 = np.cross(n_cam, los)
        axis = np.cos(a) * los + np.sin(a) * e2
        R = _rotation_from_pairs(axis, n_cam, y_body, n_body)
    elif case == "end-on":
        tilt = np.radians(3.0)
        axis = _unit(np.cos(tilt) * los + np.sin(tilt) * _unit(np.cross(los, rng.normal(size=3))))
        n_cam = _unit(np.cross(axis, rng.normal(size=3)))
        R = _rotation_from_pairs(axis, n_cam, y_body, n_body)
    else:
        R = Rotation.random(random_state=rng).as_matrix()
    axis_cam, n_cam = R @ y_body, R @ n_body
    if case == "normal":
        if abs(axis_cam @ los) > np.cos(np.radians(MIN_AXIS_TO_LOS_DEG)):
            return None, None
        if abs(n_cam @ los) < np.cos(np.radians(MAX_NORMAL_TO_LOS_DEG)):
            return None, None
    n_vis = n_cam if n_cam @ los < 0 else -n_cam  # the face toward the camera
    for _ in range(100):
        sun = _unit(rng.normal(size=3))
        if n_vis @ sun >= MIN_SUN_COS or (case == "edge-on" and sun @ -los > 0.3):
            return R, sun
    return None, None


def _rotation_from_pairs(a_cam: FloatArray, n_cam: FloatArray, a_body: FloatArray, n_body: FloatArray) -> FloatArray:
    """The rotation taking the orthonormal pair (a_body, n_body) onto (a_cam, n_cam)."""
    n_cam = _unit(n_cam - (n_cam @ a_cam) * a_cam)
    C = np.column_stack([a_cam, n_cam, np.cross(a_cam, n_cam)])
    B = np.column_stack([a_body, n_body, np.cross(a_body, n_body)])
    return np.asarray(C @ B.T, dtype=float)


def _sensor(regime: Regime, noise: bool, bits: int | None) -> SensorModel:
    if regime == "near":
        return SensorModel(bits=bits or 8, electrons_full=16000.0, psf_sigma_px=0.6, noise=noise)
    b = bits or 16
    scale = 1.0 if b == 16 else 1 / 40
    return SensorModel(
        bits=b,
        electrons_full=240000.0 * scale,
        psf_sigma_px=1.8,
        sky_dn=150.0 * scale,
        sky_gradient_dn=60.0 * scale,
        stars=3,
        noise=noise,
    )


def _meta(camera: PinholeCamera, az: float, el: float, range_m: float, craft: Spacecraft, image: str) -> dict[str, Any]:
    return {
        "schema": INPUT_SCHEMA,
        "image": image,
        "camera": {
            "model": "pinhole",
            "width_px": camera.width_px,
            "height_px": camera.height_px,
            "fx_px": camera.fx_px,
            "fy_px": camera.fy_px,
            "cx_px": camera.cx_px,
            "cy_px": camera.cy_px,
            "skew": 0.0,
            "distortion": None,
        },
        "pointing": {"frame": "station_enu", "azimuth_deg": az, "elevation_deg": el, "roll_deg": 0.0},
        "station": dict(STATION),
        "prior": {
            "range_m": range_m,
            "panel_length_m": craft.panel_length_m,
            "panel_width_m": craft.panel_width_m,
            "wings": 2,
        },
    }


def _truth(
    camera: PinholeCamera,
    craft: Spacecraft,
    R: FloatArray,
    t_cam_m: FloatArray,
    sun: FloatArray,
    R_cam_enu: FloatArray,
    regime: Regime,
    case: Case,
    seed: int,
    noise: bool,
) -> dict[str, Any]:
    axis_cam = R @ np.array([0.0, 1.0, 0.0])
    los = t_cam_m / np.linalg.norm(t_cam_m)
    axis_enu = canonical(R_cam_enu.T @ axis_cam, 1)
    axis_ecef = canonical(R_ecef_from_enu(STATION["lat_deg"], STATION["lon_deg"]) @ axis_enu, 1)
    pitch, yaw = pitch_yaw_deg(axis_enu)
    n_cam = R @ craft.panel_normal_body
    face = 1.0 if n_cam @ los < 0 else -1.0
    corners = {
        str(int(side)): camera.project(craft.wing_corners_body(side, face) @ R.T + t_cam_m).tolist()
        for side in (1.0, -1.0)
    }
    expected = {
        "blank": {"code": "no_target"},
        "edge-on": {"code": "degenerate_view"},
        "end-on": {"code": "degenerate_view"},
    }.get(case)
    return {
        "seed": seed,
        "regime": regime,
        "case": case,
        "noise": noise,
        "axis_camera": canonical(axis_cam, 0).tolist(),
        "axis_station_enu": axis_enu.tolist(),
        "axis_ecef": axis_ecef.tolist(),
        "pitch_deg": pitch,
        "yaw_deg": yaw,
        "mirror_camera": canonical(axis_cam - 2 * (axis_cam @ los) * los, 0).tolist(),
        "panel_normal_camera": n_cam.tolist(),
        "axis_to_los_deg": float(np.degrees(np.arccos(min(1.0, abs(float(axis_cam @ los)))))),
        "normal_to_los_deg": float(np.degrees(np.arccos(min(1.0, abs(float(n_cam @ los)))))),
        "sigma_crlb_deg": crlb_sigma_deg(camera, craft, R, t_cam_m) if case == "normal" else None,
        "wing_corners_px": corners,
        "R_cam_from_body": R.tolist(),
        "t_cam_m": t_cam_m.tolist(),
        "sun_camera": sun.tolist(),
        "spacecraft": craft.model_dump(),
        "expected_error": expected,
    }


def crlb_sigma_deg(camera: PinholeCamera, craft: Spacecraft, R: FloatArray, t_cam_m: FloatArray) -> float:
    """The bound (largest 1σ, deg) on the axis from the four long wing edges of the visible faces,
    each sampled every pixel with 0.05 px noise (occlusion ignored)."""
    los = t_cam_m / np.linalg.norm(t_cam_m)
    face = 1.0 if (R @ craft.panel_normal_body) @ los < 0 else -1.0
    planes = []
    for side in (1.0, -1.0):
        c = camera.project(craft.wing_corners_body(side, face) @ R.T + t_cam_m)
        for a, b in ((c[0], c[1]), (c[3], c[2])):
            length = float(np.hypot(*(b - a)))
            n = max(int(length), 2)
            var_offset = CRLB_POINT_SIGMA_PX**2 / n
            var_angle = CRLB_POINT_SIGMA_PX**2 / (n * length**2 / 12)
            angle = float(np.arctan2(b[1] - a[1], b[0] - a[0]))
            planes.append(plane_obs(camera, (a + b) / 2, angle, var_offset, var_angle))
    cov = direction_bound(planes, R @ np.array([0.0, 1.0, 0.0]))
    return float(np.degrees(np.sqrt(np.linalg.eigvalsh(cov).max())))


def _break(meta: dict[str, Any], field: str, R_cam_enu: FloatArray) -> None:
    """Spoil ``field`` of a valid meta dict."""
    cam = meta["camera"]
    if field == "schema":
        meta["schema"] = "tumblescan.panel_axis.input/9"
    elif field == "camera.fx_px":
        cam["fx_px"] = -cam["fx_px"]
    elif field == "camera.cx_px":
        cam["cx_px"] = cam["width_px"] + 10.0
    elif field == "camera.width_px":
        cam["width_px"] += 2
        cam["cx_px"] = (cam["width_px"] - 1) / 2
    elif field == "pointing.elevation_deg":
        meta["pointing"]["elevation_deg"] = 95.0
    elif field == "camera.fy_px":
        cam["fy_px"] = float("nan")
    elif field == "pointing.R_cam_from_ref":
        bad = R_cam_enu.copy()
        bad[0] *= 1.01
        meta["pointing"] = {"frame": "station_enu", "R_cam_from_ref": bad.tolist()}
    elif field == "prior.panel_length_m":
        meta["prior"]["panel_length_m"] = 0.0
    elif field == "camera.distortion":
        cam["distortion"] = [0.01, 0.0, 0.0]


def _unit(v: FloatArray) -> FloatArray:
    return np.asarray(v / np.linalg.norm(v), dtype=float)
