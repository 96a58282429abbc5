"""Simulated tag detections (level B) from the paper's four-camera rig, with known truth.

The rig: the paper's four cameras (2048 x 2048 px, 5.5 um pixels, f = 12.5 mm, so f = 2273 px) at
the top corners of the 6 x 6 x 3 m volume, looking at its centre (the level-A simulator's rig).
The target: the 440 x 340 x 260 mm box carrying ten AprilTag 36h11 tags of 120 mm (two on each
large face, one on each end), moving as the paper's sinusoids or a tumble. A camera detects a
tag whose face is turned less than ``max_view_deg`` from it and whose corners lie in the image;
detections are the exact projections plus Gaussian noise (0.25 px per axis), with random misses,
a few gross errors (a whole tag shifted by 3-10 px) and short gaps with no detection at all.

The truth holds every pose and the per-frame bound ``C_k = (sum J^T J / sigma^2)^-1`` over the
inlier detections, ``J`` the projection Jacobian of each corner (``tag_camera``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from .._typing import FloatArray, IntArray
from .geometry import exp_so3, quat_wxyz
from .simulate import CAMERAS_M, CENTRE_M, motion
from .tag_camera import RigArrays, RigCamera, body_to_pixels, pose_information_px, project, tag_corners_body, to_camera

PAPER_SENSOR_PX = 2048
PAPER_FOCAL_PX = 12.5e-3 / 5.5e-6
BOX_HALF_M = np.array([0.22, 0.17, 0.13])


class TagSimConfig(BaseModel):
    """What to simulate at level B (and the scene level C renders)."""

    model_config = ConfigDict(extra="forbid")

    motion: Literal["paper", "tumble"] = "paper"
    frames: int = Field(500, ge=3, le=200_000)
    frame_rate_hz: float = Field(50.0, gt=0)
    pixel_sigma_px: float = Field(0.25, ge=0)
    binning: int = Field(1, ge=1, le=8, description="pixels binned per side (level C renders at 2: 1024 px)")
    tag_size_m: float = Field(0.12, gt=0)
    max_view_deg: float = Field(70.0, gt=0, lt=90)
    distortion: tuple[float, float, float, float, float] = (-0.05, 0.01, 0.0, 0.0, 0.0)
    miss_fraction: float = Field(0.02, ge=0, le=0.5)
    outlier_fraction: float = Field(0.003, ge=0, le=0.2)
    gaps: int = Field(3, ge=0)


@dataclass
class TagSimulation:
    config: TagSimConfig
    cameras: list[RigCamera]
    T_body_tag: FloatArray  # (T, 4, 4)
    tag_ids: list[int]
    t_s: FloatArray
    R_world_body: FloatArray
    t_world_m: FloatArray
    det_frame: list[int] = field(default_factory=list)
    det_cam: list[int] = field(default_factory=list)
    det_tag: list[int] = field(default_factory=list)  # index into tag_ids
    corners_px: list[FloatArray] = field(default_factory=list)
    outlier: list[bool] = field(default_factory=list)

    def scene(self) -> dict[str, Any]:
        """The document without detections (cameras, tags, frames): level C's scene.json."""
        return {
            "format": "tumblescan.tags.v1",
            "units": {"length": "m", "time": "s"},
            "frame_rate_hz": self.config.frame_rate_hz,
            "cameras": [
                {
                    "id": c.id,
                    "width": c.width_px,
                    "height": c.height_px,
                    "K": c.K.tolist(),
                    "dist": c.dist.tolist(),
                    "T_world_cam": _matrix(c.R_world_cam, c.t_world_cam),
                    "pixel_sigma": c.pixel_sigma_px,
                }
                for c in self.cameras
            ],
            "tags": {
                "family": "tag36h11",
                "size_m": self.config.tag_size_m,
                "layout": [
                    {"id": i, "T_body_tag": np.round(T, 12).tolist()}
                    for i, T in zip(self.tag_ids, self.T_body_tag, strict=True)
                ],
            },
            "frames": [{"frame": k, "t": round(float(t), 9)} for k, t in enumerate(self.t_s)],
        }

    def document(self) -> dict[str, Any]:
        """The level-B input document (``tumblescan.tags.v1``)."""
        doc = self.scene()
        doc["detections"] = [
            {
                "frame": f,
                "t": round(float(self.t_s[f]), 9),
                "camera": self.cameras[c].id,
                "id": self.tag_ids[j],
                "corners_px": np.round(uv, 4).tolist(),
            }
            for f, c, j, uv in zip(self.det_frame, self.det_cam, self.det_tag, self.corners_px, strict=True)
        ]
        return doc

    def truth(self, detected: list[tuple[int, int, int]] | None = None) -> dict[str, Any]:
        """Every pose and the per-frame bound over the inlier detections (or over ``detected``:
        (frame, camera, tag index) triples, for level C). Same layout as the level-A truth."""
        rig = RigArrays.of(self.cameras)
        corners = tag_corners_body(self.T_body_tag, self.config.tag_size_m)
        if detected is None:
            detected = [
                (f, c, j)
                for f, c, j, bad in zip(self.det_frame, self.det_cam, self.det_tag, self.outlier, strict=True)
                if not bad
            ]
        per_frame: dict[int, list[tuple[int, int]]] = {}
        for f, c, j in detected:
            per_frame.setdefault(f, []).append((c, j))
        frames = []
        for k in range(len(self.t_s)):
            seen = per_frame.get(k, [])
            crlb = None
            if seen:
                cam = np.array([c for c, _ in seen], dtype=np.int64)
                info = pose_information_px(
                    self.R_world_body[k], self.t_world_m[k], corners[[j for _, j in seen]], cam, rig
                )
                if np.linalg.cond(info) < 1e12:
                    crlb = np.linalg.inv(info).tolist()
            frames.append(
                {
                    "frame": k,
                    "t": float(self.t_s[k]),
                    "q_wxyz": quat_wxyz(self.R_world_body[k]).tolist(),
                    "t_m": self.t_world_m[k].tolist(),
                    "inlier_markers": sorted({str(self.tag_ids[j]) for _, j in seen}),
                    "crlb": crlb,
                    "crlb_self_calibrated": crlb,
                }
            )
        return {
            "format": "tumblescan.tags.truth.v1",
            "config": self.config.model_dump(mode="json"),
            "layout": {"ids": [str(i) for i in self.tag_ids], "xyz": self.T_body_tag[:, :3, 3].tolist()},
            "tracks": {},
            "frames": frames,
        }


def _matrix(R: FloatArray, t: FloatArray) -> list[list[float]]:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return [[round(float(v), 12) for v in row] for row in T]


def paper_rig(
    binning: int = 1, pixel_sigma_px: float = 0.25, distortion: tuple[float, ...] = (0.0,) * 5
) -> list[RigCamera]:
    """The paper's four cameras at the top corners of the volume, looking at its centre
    (``binning`` pixels per side binned: 2 gives 1024 x 1024 px of 11 um)."""
    side = PAPER_SENSOR_PX // binning
    f = PAPER_FOCAL_PX / binning
    c = (side - 1) / 2.0
    K = np.array([[f, 0.0, c], [0.0, f, c], [0.0, 0.0, 1.0]])
    cams = []
    for i, pos in enumerate(CAMERAS_M):
        z = CENTRE_M - pos
        z /= np.linalg.norm(z)
        x = np.cross(z, [0.0, 0.0, 1.0])
        x /= np.linalg.norm(x)
        R = np.column_stack([x, np.cross(z, x), z])  # camera axes in the world: x right, y down, z forward
        cams.append(RigCamera(f"cam{i + 1}", side, side, K, np.array(distortion, float), R, pos.copy(), pixel_sigma_px))
    return cams


def box_tags(size_m: float) -> FloatArray:
    """T_body_tag (10, 4, 4) of the box's tags: two on each 440 mm face (top, bottom, +-y), one at
    each end (+-x); each tag's z out of its face and its x along the face."""
    h = BOX_HALF_M
    spots = [
        (np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), [h[0], 0.0, 0.0]),
        (np.array([-1.0, 0, 0]), np.array([0, -1.0, 0]), [-h[0], 0.0, 0.0]),
    ]
    for dx in (-0.11, 0.11):
        spots += [
            (np.array([0, 0, 1.0]), np.array([1.0, 0, 0]), [dx, 0.02, h[2]]),
            (np.array([0, 0, -1.0]), np.array([1.0, 0, 0]), [dx, -0.02, -h[2]]),
            (np.array([0, 1.0, 0]), np.array([-1.0, 0, 0]), [dx, h[1], 0.0]),
            (np.array([0, -1.0, 0]), np.array([1.0, 0, 0]), [dx, -h[1], 0.0]),
        ]
    out = []
    for n, x, p in spots:
        T = np.eye(4)
        T[:3, :3] = np.column_stack([x, np.cross(n, x), n])
        T[:3, 3] = p
        out.append(T)
    del size_m  # the spots fit tags up to 160 mm with their white margin of one cell
    return np.array(out)


def visible_tags(
    R: FloatArray, t: FloatArray, T_body_tag: FloatArray, size_m: float, cameras: list[RigCamera], max_view_deg: float
) -> FloatArray:
    """(F, C, T) bool: the tag's face is turned less than ``max_view_deg`` from the camera and its
    corners are at least 3 px inside the image."""
    F, T = len(R), len(T_body_tag)
    rig = RigArrays.of(cameras)
    corners = tag_corners_body(T_body_tag, size_m)
    centre_w = np.einsum("fij,tj->fti", R, T_body_tag[:, :3, 3]) + t[:, None]
    normal_w = np.einsum("fij,tj->fti", R, T_body_tag[:, :3, 2])
    out = np.zeros((F, len(cameras), T), dtype=bool)
    for c, cam in enumerate(cameras):
        d = cam.t_world_cam - centre_w
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        facing = np.einsum("fti,fti->ft", d, normal_w) > np.cos(np.radians(max_view_deg))
        pw = np.einsum("fij,tpj->ftpi", R, corners) + t[:, None, None]
        pc = to_camera(pw.reshape(F * T, 4, 3), np.full(F * T, c), rig)
        uv = project(pc, np.full(F * T, c), rig).reshape(F, T, 4, 2)
        inside = (
            (pc[..., 2].reshape(F, T, 4) > 0).all(-1)
            & (uv >= 3).all(axis=(-1, -2))
            & (uv[..., 0] <= cam.width_px - 4).all(-1)
            & (uv[..., 1] <= cam.height_px - 4).all(-1)
        )
        out[:, c] = facing & inside
    return out


def simulate_tags(config: TagSimConfig, seed: int) -> TagSimulation:
    """Simulate ``config`` with the random generator seeded by ``seed``."""
    rng = np.random.default_rng(seed)
    F = config.frames
    t_s = np.arange(F) / config.frame_rate_hz
    R, t = motion(rng, config.motion, t_s)
    if config.motion == "paper":  # turn the box so that both its top and its sides face the cameras
        R = R @ exp_so3(np.array([np.radians(35.0), 0.0, 0.0]))
    cams = paper_rig(config.binning, max(config.pixel_sigma_px, 1e-3), config.distortion)
    T_bt = box_tags(config.tag_size_m)
    sim = TagSimulation(config, cams, T_bt, list(range(len(T_bt))), t_s, R, t)
    seen = visible_tags(R, t, T_bt, config.tag_size_m, cams, config.max_view_deg)
    empty = np.zeros(F, dtype=bool)
    for k in range(config.gaps):
        start = int((k + 1) * F / (config.gaps + 1) + rng.integers(-F // 20, F // 20 + 1))
        empty[max(start, 1) : max(start, 1) + int(rng.integers(1, 6))] = True
    rig = RigArrays.of(cams)
    corners = tag_corners_body(T_bt, config.tag_size_m)
    f_idx, c_idx, j_idx = np.nonzero(seen & ~empty[:, None, None])
    keep = rng.random(len(f_idx)) >= config.miss_fraction
    f_idx, c_idx, j_idx = f_idx[keep], c_idx[keep], j_idx[keep]
    uv = _exact_corners(R, t, corners, f_idx, c_idx, j_idx, rig)
    uv = uv + rng.normal(0.0, config.pixel_sigma_px, uv.shape)
    bad = rng.random(len(f_idx)) < config.outlier_fraction
    for i in np.flatnonzero(bad):
        u = rng.normal(size=2)
        uv[i] += u / np.linalg.norm(u) * rng.uniform(3.0, 10.0)
    sim.det_frame = f_idx.tolist()
    sim.det_cam = c_idx.tolist()
    sim.det_tag = j_idx.tolist()
    sim.corners_px = list(uv)
    sim.outlier = bad.tolist()
    return sim


def _exact_corners(
    R: FloatArray, t: FloatArray, corners: FloatArray, f: IntArray, c: IntArray, j: IntArray, rig: RigArrays
) -> FloatArray:
    return body_to_pixels(R[f], t[f], corners[j], c, rig)
