"""Seeded image sequences of a flat-spinning box-bus satellite, with the truth and the bound.

Physics (digest §6(d)): the target spins torque-free about its major principal axis through the
centre of mass, ``R(t) = Rot(a, ω t)·R_ref``, the centre fixed (or drifting slowly); a fixed
pinhole camera; frames at irregular mid-exposure times with one interior frame dropped; each frame
the mean of renders over the exposure (motion blur), then PSF, sky, stars, shot and read noise and
8/16-bit quantization. Kinds: the axis ``oblique`` (15-75° from the line of sight), near the line
of sight (``los``, 0-8°) or near the image plane (``plane``, 84-90°); ``static``; ``aliased``
(200-300° per frame, with a prior that admits it); ``blank`` (no target), ``corrupt`` (a truncated
PNG) and ``broken-meta`` (one bad field in meta.json, see :data:`BROKEN_META`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from .._typing import FloatArray
from ..geometry.rotations import tangent_basis
from ..imaging.blur import render_exposure
from ..imaging.camera import PinholeCamera, camera_from_fov
from ..imaging.image_io import write_image
from ..imaging.sensor import SensorModel, expose
from .bound import rate_crb
from .meta import INPUT_SCHEMA
from .rotation import los_angle_deg, mirror_twin, rot, unit_from_angles
from .spacecraft import Target, random_target

SimKind = Literal["oblique", "los", "plane", "static", "aliased", "blank", "corrupt", "broken-meta"]
SIM_KINDS: tuple[str, ...] = ("oblique", "los", "plane", "static", "aliased", "blank", "corrupt", "broken-meta")
AXIS_LOS_DEG = {"oblique": (15.0, 75.0), "los": (0.0, 8.0), "plane": (84.0, 90.0)}
CRB_SIGMA_PX = 0.5
ELECTRONS_PER_DN = 30.0

# Broken meta.json variants: name -> the field the refusal must name.
BROKEN_META: dict[str, str] = {
    "unknown_schema": "schema",
    "swapped_times": "frames.2.t_s",
    "nan_time": "frames.3.t_s",
    "missing_fx": "camera.fx_px",
    "wrong_width": "camera.width_px",
    "missing_frame": "frames.5.file",
    "four_frames": "frames",
    "negative_exposure": "exposure_s",
}


@dataclass
class Sequence:
    """Frames (file name -> one image per noise setting), meta.json and truth.json of one sequence."""

    images: list[dict[str, np.ndarray]]
    meta: dict[str, Any]
    truth: dict[str, Any]
    corrupt: set[str] = field(default_factory=set)


def simulate_sequence(
    seed: int,
    kind: SimKind = "oblique",
    *,
    noises: tuple[bool, ...] = (False,),
    width_px: int = 512,
    height_px: int | None = None,
    frames: int = 16,
    bits: int = 8,
    tiff: bool = False,
    drift: bool = False,
    broken: str | None = None,
) -> Sequence:
    """Render one seeded sequence (once per entry of ``noises``: the clean and noisy twins share
    the geometry and the radiance)."""
    rng = np.random.default_rng(seed)
    H = height_px or width_px
    target = random_target(rng)
    radius = target.mesh.bounding_radius_m
    # Camera and range: the bounding sphere fills 55-80 % of the width, off centre.
    camera = camera_from_fov(width_px, H, float(rng.uniform(14, 28)))
    fill = float(rng.uniform(0.55, 0.8))
    range_m = radius * camera.fx_px / (0.5 * fill * width_px)
    room = (1 - fill) / 2 * 0.8
    off = rng.uniform(-room, room, 2) * np.array([width_px, H])
    c_m = np.array([off[0] / camera.fx_px * range_m, off[1] / camera.fy_px * range_m, range_m])
    # Spin: the axis at the kind's angle from the line of sight, either sense; the rate and frame step.
    lo, hi = AXIS_LOS_DEG.get(kind, (15.0, 75.0))
    a = unit_from_angles(np.radians(rng.uniform(lo, hi)), rng.uniform(0, 2 * np.pi))
    a = a if rng.random() < 0.5 else -a
    rate_deg_s = float(rng.uniform(2.0, 45.0))
    step_deg = float(rng.uniform(200.0, 300.0)) if kind == "aliased" else float(rng.uniform(8.0, 22.0))
    dt = step_deg / rate_deg_s
    if kind == "static":
        rate_deg_s = 0.0
    omega = np.radians(rate_deg_s)
    # R_ref takes the body's major axis onto a, with a random phase about it.
    R_ref = _align(target.major_axis_body, a) @ rot(target.major_axis_body, rng.uniform(0, 2 * np.pi))[0]
    # Times: frames+1 nominal instants, one interior dropped, ±3 % jitter; mid-exposure.
    t_nom = np.arange(frames + 1) * dt
    t_s = np.delete(t_nom + rng.uniform(-0.03, 0.03, frames + 1) * dt, int(rng.integers(2, frames - 1)))
    t_s = np.round(t_s - t_s[0], 6)
    exposure_s = float(rng.uniform(0.002, 0.015))
    n_blur = int(np.clip(np.ceil(rate_deg_s * exposure_s / 0.2), 1, 5))
    v_m_s = np.zeros(3)
    if drift:
        e1, _ = tangent_basis(np.array([0.0, 0.0, 1.0]))
        d_dir = rot(np.array([0.0, 0.0, 1.0]), rng.uniform(0, 2 * np.pi))[0] @ e1
        v_m_s = d_dir * rng.uniform(0.3, 1.5) * range_m / camera.fx_px / dt
    # The sun at 20-75° phase angle.
    to_cam = -c_m / np.linalg.norm(c_m)
    perp, _ = tangent_basis(to_cam)
    sun = rot(to_cam, rng.uniform(0, 2 * np.pi))[0] @ rot(perp, np.radians(rng.uniform(20, 75)))[0] @ to_cam

    def pose(t: float) -> tuple[FloatArray, FloatArray]:
        return rot(a, omega * t)[0] @ R_ref, c_m + v_m_s * t

    sensors = [_sensor(rng, noisy, bits) for noisy in noises]
    images: list[dict[str, np.ndarray]] = [{} for _ in noises]
    ext = "tif" if tiff else "png"
    names = [f"frames/frame_{i:03d}.{ext}" for i in range(len(t_s))]
    for name, t in zip(names, t_s, strict=True):
        offsets = (np.arange(n_blur) + 0.5) / n_blur - 0.5 if n_blur > 1 else np.zeros(1)
        if kind == "blank":
            radiance = np.zeros((H, width_px))
        else:
            radiance = render_exposure(target.mesh, camera, [pose(t + o * exposure_s) for o in offsets], sun).radiance
        for k, sensor in enumerate(sensors):
            images[k][name] = expose(radiance, sensor, np.random.default_rng([seed, k, int(t * 1e6)]))
    prior_max = float(np.round(min(1.2 * rate_deg_s, 400.0) if kind == "aliased" else 90.0 / dt, 3))
    meta = {
        "schema": INPUT_SCHEMA,
        "frames": [{"file": n, "t_s": float(t)} for n, t in zip(names, t_s, strict=True)],
        "time_reference": "mid_exposure",
        "exposure_s": round(exposure_s, 6),
        "epoch_utc": None,
        "camera": {"model": "pinhole", "width_px": width_px, "height_px": H, "fx_px": camera.fx_px,
                   "fy_px": camera.fy_px, "cx_px": camera.cx_px, "cy_px": camera.cy_px, "skew": 0.0,
                   "distortion": None, "pixel_origin": "center_of_top_left_pixel"},
        "prior": {"motion": "single_axis_spin", "max_rate_deg_s": prior_max, "min_rate_deg_s": 0.5,
                  "target_polarity": "bright"},
        "options": {"return_tracks": False},
    }  # fmt: skip
    truth = _truth(kind, target, camera, R_ref, a, omega, c_m, v_m_s, t_s, dt, exposure_s, n_blur)
    seq = Sequence(images, meta, truth)
    if kind == "corrupt":
        seq.corrupt.add(names[len(names) // 2])
    if kind == "broken-meta":
        how = broken or list(BROKEN_META)[seed % len(BROKEN_META)]
        break_meta(meta, how)
        truth["broken"] = {"how": how, "field": BROKEN_META[how]}
    return seq


def break_meta(meta: dict[str, Any], how: str) -> None:
    """Break ``meta`` in place the way ``how`` (a key of :data:`BROKEN_META`) names."""
    f = meta["frames"]
    if how == "unknown_schema":
        meta["schema"] = "tumblescan.spin_from_images.input/9"
    elif how == "swapped_times":
        f[1]["t_s"], f[2]["t_s"] = f[2]["t_s"], f[1]["t_s"]
    elif how == "nan_time":
        f[3]["t_s"] = float("nan")
    elif how == "missing_fx":
        del meta["camera"]["fx_px"]
    elif how == "wrong_width":
        meta["camera"]["width_px"] += 16
    elif how == "missing_frame":
        f[5]["file"] = "frames/not_there.png"
    elif how == "four_frames":
        del f[4:]
    elif how == "negative_exposure":
        meta["exposure_s"] = -0.01
    else:
        raise ValueError(f"unknown way to break meta.json: {how}")


def write_sequence(out: Path, seq: Sequence, which: int = 0) -> Path:
    """Write frames, meta.json and truth.json under ``out``; returns meta.json's path."""
    (out / "frames").mkdir(parents=True, exist_ok=True)
    for name, img in seq.images[which].items():
        path = out / name
        write_image(path, img)
        if name in seq.corrupt:  # truncated mid-stream
            data = path.read_bytes()
            path.write_bytes(data[: len(data) // 3])
    (out / "meta.json").write_text(json.dumps(seq.meta, indent=1))
    (out / "truth.json").write_text(json.dumps(seq.truth, indent=1))
    return out / "meta.json"


def _sensor(rng: np.random.Generator, noisy: bool, bits: int) -> SensorModel:
    full = 220.0 * ELECTRONS_PER_DN * (1.0 if bits == 8 else 100.0)
    return SensorModel(
        bits=bits, electrons_full=full, electrons_per_dn=ELECTRONS_PER_DN,
        psf_sigma_px=float(rng.uniform(0.5, 0.8)), read_noise_dn=1.5, sky_dn=float(rng.uniform(2, 4)),
        sky_gradient_dn=1.0, stars=int(rng.integers(5, 21)) if noisy else 0, noise=noisy,
    )  # fmt: skip


def _align(u: FloatArray, v: FloatArray) -> FloatArray:
    """The smallest rotation taking unit ``u`` onto unit ``v``."""
    axis = np.cross(u, v)
    s = float(np.linalg.norm(axis))
    if s < 1e-12:
        return np.eye(3) if float(np.dot(u, v)) > 0 else rot(tangent_basis(u)[0], np.pi)[0]
    return rot(axis / s, np.arctan2(s, float(np.dot(u, v))))[0]


def _truth(
    kind: str, target: Target, camera: PinholeCamera, R_ref: FloatArray, a: FloatArray, omega: float,
    c_m: FloatArray, v_m_s: FloatArray, t_s: FloatArray, dt: float, exposure_s: float, n_blur: int,
) -> dict[str, Any]:  # fmt: skip
    """The truth: rate, axis and twin, sense, corner tracks with visibility, and the CRB."""
    Q = target.corners_m @ R_ref.T
    uv, visible = corner_tracks(target, camera, R_ref, a, omega, c_m, v_m_s, t_s)
    sigma = rate_crb(camera, a, omega, c_m, Q, t_s, visible, CRB_SIGMA_PX) if omega > 0 else None
    rate = float(np.degrees(omega))
    return {
        "kind": kind,
        "rate_deg_s": rate,
        "axis_camera": a.tolist(),
        "mirror_axis_camera": mirror_twin(a).tolist(),
        "sense_about_los": int(np.sign(a[2])) if abs(a[2]) > 1e-12 else 0,
        "axis_los_angle_deg": los_angle_deg(a),
        "center_camera_m": c_m.tolist(),
        "velocity_camera_m_s": v_m_s.tolist(),
        "reference_time_s": 0.0,
        "nominal_step_deg": float(np.degrees(omega) * dt),
        "revolutions": float(np.degrees(omega) * (t_s[-1] - t_s[0]) / 360.0),
        "exposure_s": exposure_s,
        "blur_samples": n_blur,
        "sigma_rate_crb_deg_s": None if sigma is None else float(np.degrees(sigma)),
        "crb_sigma_px": CRB_SIGMA_PX,
        "corners_uv_px": np.round(uv, 3).tolist(),
        "corners_visible": visible.tolist(),
    }


def corner_tracks(
    target: Target, camera: PinholeCamera, R_ref: FloatArray, a: FloatArray, omega: float,
    c_m: FloatArray, v_m_s: FloatArray, t_s: FloatArray,
) -> tuple[FloatArray, np.ndarray]:  # fmt: skip
    """Image positions (frames, corners, 2) of the corners and whether each is seen (not hidden by
    the target, inside the image), by ray casting in the body frame."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(target.mesh.vertices_m.astype(np.float32)),  # type: ignore[call-overload]
        o3d.core.Tensor(target.mesh.triangles.astype(np.uint32)),  # type: ignore[call-overload]
    )
    P = target.corners_m
    uvs, vis = [], []
    for t in t_s:
        R = rot(a, omega * t)[0] @ R_ref
        c = c_m + v_m_s * t
        p_cam = P @ R.T + c
        uv = camera.project(p_cam)
        origin = R.T @ (-c)
        d = P - origin
        dist = np.linalg.norm(d, axis=1)
        rays = np.hstack([np.broadcast_to(origin, d.shape), d / dist[:, None]]).astype(np.float32)
        cast = scene.cast_rays(o3d.core.Tensor(rays))  # type: ignore[call-overload]
        t_hit = cast["t_hit"].numpy().astype(float)
        inside = (uv[:, 0] > 0) & (uv[:, 0] < camera.width_px - 1) & (uv[:, 1] > 0) & (uv[:, 1] < camera.height_px - 1)
        uvs.append(uv)
        vis.append((t_hit >= dist - 0.01) & inside)
    return np.array(uvs), np.array(vis)
