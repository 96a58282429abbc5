"""Reading and validating level-B input (``tumblescan.tags.v1``): calibrated cameras, the tags'
layout on the body and tag corner detections; level C's scene is the same document without
detections, with ``frames``.

Everything is checked once here, at the door; the estimator trusts what this returns.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._typing import FloatArray, IntArray
from ..io.manifest import first_non_finite
from .errors import (
    DuplicateObservationError,
    InputError,
    LimitExceededError,
    MalformedInputError,
    NoiseOutOfRangeError,
    NonFiniteValueError,
    TimeOrderError,
    TooFewFramesError,
    UnknownFieldError,
)
from .markers_io import _check_units, _is_number, _load_json, is_frame_number
from .options import MarkerPoseLimits
from .tag_camera import RigCamera, tag_corners_body

FORMAT = "tumblescan.tags.v1"
FAMILIES = ("tag36h11", "tag25h9", "tag16h5")
TOP_KEYS = {"format", "units", "frame_rate_hz", "cameras", "tags", "detections", "frames"}
CAMERA_KEYS = {"id", "width", "height", "K", "dist", "T_world_cam", "pixel_sigma"}
MAX_ENTRY = 1e9  # larger matrix entries are nonsense here (and would overflow the checks)
DETECTION_KEYS = {"frame", "t", "camera", "id", "corners_px"}


class BadCameraError(InputError):
    code = "invalid_camera"


class BadCornersError(InputError):
    code = "invalid_corners"


class UnknownFamilyError(InputError):
    code = "unknown_family"


@dataclass
class TagInput:
    """Validated level-B input. cameras: the rig; tag_ids (T,) and T_body_tag (T, 4, 4) [m]: the
    layout; corners_body_m (T, 4, 3): each tag's corners TL, TR, BR, BL in the body frame;
    frames (F,), t_s (F,): frame numbers and times; det_frame (N,) index into ``frames``;
    det_cam (N,) index into ``cameras``; det_tag (N,) index into ``tag_ids``; corners_px (N, 4, 2)."""

    cameras: list[RigCamera]
    family: str
    size_m: float
    tag_ids: list[int]
    T_body_tag: FloatArray
    frames: IntArray
    t_s: FloatArray
    det_frame: IntArray
    det_cam: IntArray
    det_tag: IntArray
    corners_px: FloatArray
    frame_rate_hz: float | None
    warnings: list[str] = field(default_factory=list)

    @property
    def corners_body_m(self) -> FloatArray:
        return tag_corners_body(self.T_body_tag, self.size_m)

    @property
    def n_frames(self) -> int:
        return len(self.frames)


def read_tags(path: Path, limits: MarkerPoseLimits | None = None) -> TagInput:
    """Read and validate a ``tumblescan.tags.v1`` JSON file (part ``tags``)."""
    return tags_from_json(_load_json(path, "tags"), limits=limits)


def tags_from_json(doc: Any, *, limits: MarkerPoseLimits | None = None, require_detections: bool = True) -> TagInput:
    """Validate a ``tumblescan.tags.v1`` document; every refusal names its field. Without
    ``require_detections`` (level C's scene) the detections may be absent and ``frames`` is required."""
    limits = limits or MarkerPoseLimits()
    if not isinstance(doc, dict):
        raise MalformedInputError("the tags document must be a JSON object", field="input")
    unknown = sorted(set(doc) - TOP_KEYS)
    if unknown:
        raise UnknownFieldError(f"unknown field {unknown[0]!r}", field=unknown[0])
    if doc.get("format") != FORMAT:
        raise MalformedInputError(f"format must be {FORMAT!r}, not {doc.get('format')!r}", field="format")
    bad = first_non_finite(doc)
    if bad is not None:
        bad = _bracketed(bad)
        raise NonFiniteValueError(f"{bad} is not a finite number (NaN and Infinity are refused)", field=bad)
    _check_units(doc.get("units"))
    rate = doc.get("frame_rate_hz")
    if rate is not None and (not _is_number(rate) or rate <= 0):
        raise MalformedInputError("frame_rate_hz must be a positive number", field="frame_rate_hz")
    cameras = _cameras(doc.get("cameras"), limits)
    family, size_m, tag_ids, T_body_tag = _tags(doc.get("tags"), limits)
    warnings: list[str] = []
    frames_doc = doc.get("frames")
    dets = doc.get("detections")
    if require_detections and (not isinstance(dets, list) or not dets):
        raise MalformedInputError("detections must be a non-empty list", field="detections")
    if not require_detections and frames_doc is None:
        raise MalformedInputError("frames [{frame, t}] is required with images", field="frames")
    frame_t = _frames(frames_doc, limits) if frames_doc is not None else None
    out = TagInput(
        cameras=cameras,
        family=family,
        size_m=size_m,
        tag_ids=tag_ids,
        T_body_tag=T_body_tag,
        frames=np.zeros(0, dtype=np.int64),
        t_s=np.zeros(0),
        det_frame=np.zeros(0, dtype=np.int64),
        det_cam=np.zeros(0, dtype=np.int64),
        det_tag=np.zeros(0, dtype=np.int64),
        corners_px=np.zeros((0, 4, 2)),
        frame_rate_hz=float(rate) if rate is not None else None,
        warnings=warnings,
    )
    if frame_t is not None:
        out.frames = np.array(sorted(frame_t), dtype=np.int64)
        out.t_s = np.array([frame_t[f] for f in out.frames])
    if dets:
        _detections(dets, out, frame_t, limits)
    return out


def _bracketed(dotted: str) -> str:
    """``detections.2.corners_px.1.0`` -> ``detections[2].corners_px[1][0]`` (the fields' style here)."""
    out = ""
    for part in dotted.split("."):
        out += f"[{part}]" if part.isdigit() else (f".{part}" if out else part)
    return out


def _number_matrix(value: Any, rows: int, cols: int, where: str) -> FloatArray:
    ok = (
        isinstance(value, list)
        and len(value) == rows
        and all(isinstance(r, list) and len(r) == cols and all(_is_number(v) for v in r) for r in value)
    )
    if not ok:
        raise MalformedInputError(f"{where} must be a {rows}x{cols} matrix of numbers", field=where)
    M = np.array(value, dtype=float)
    if np.max(np.abs(M)) > MAX_ENTRY:
        raise MalformedInputError(f"{where} has an entry over {MAX_ENTRY:g} in magnitude", field=where)
    return M


def rigid_transform(value: Any, where: str) -> FloatArray:
    """A 4x4 rigid transform (``R^T R = I``, ``det R = 1``, last row 0 0 0 1), else an error naming ``where``."""
    T = _number_matrix(value, 4, 4, where)
    R = T[:3, :3]
    if (
        np.max(np.abs(R.T @ R - np.eye(3))) > 1e-6
        or abs(np.linalg.det(R) - 1.0) > 1e-6
        or np.max(np.abs(T[3] - [0, 0, 0, 1])) > 1e-12
    ):
        raise BadCameraError(f"{where} is not a rigid transform (R^T R = I, det R = 1, last row 0 0 0 1)", field=where)
    return T


def _cameras(value: Any, limits: MarkerPoseLimits) -> list[RigCamera]:
    if not isinstance(value, list) or not value:
        raise MalformedInputError("cameras must be a non-empty list", field="cameras")
    if len(value) > limits.max_cameras:
        raise LimitExceededError(f"{len(value)} cameras; the limit is {limits.max_cameras}", field="cameras")
    out: list[RigCamera] = []
    for i, c in enumerate(value):
        where = f"cameras[{i}]"
        if not isinstance(c, dict):
            raise MalformedInputError(f"{where} must be an object", field=where)
        extra = sorted(set(c) - CAMERA_KEYS)
        if extra:
            raise UnknownFieldError(f"unknown field {where}.{extra[0]}", field=f"{where}.{extra[0]}")
        cid = c.get("id")
        if not isinstance(cid, str) or not cid or any(cam.id == cid for cam in out):
            raise MalformedInputError(f"{where}.id must be a unique non-empty string", field=f"{where}.id")
        size: list[int] = []
        for name in ("width", "height"):
            v = c.get(name)
            if not isinstance(v, int) or isinstance(v, bool) or not 1 <= v <= 100_000:
                raise BadCameraError(f"{where}.{name} must be a positive integer [px]", field=f"{where}.{name}")
            size.append(v)
        w, h = size
        K = _number_matrix(c.get("K"), 3, 3, f"{where}.K")
        if K[0, 0] <= 0 or K[1, 1] <= 0 or np.any(K[1:, 0] != 0) or K[2, 1] != 0 or K[2, 2] != 1:
            raise BadCameraError(
                f"{where}.K must be upper-triangular with positive focal lengths and K[2][2] = 1", field=f"{where}.K"
            )
        dist = c.get("dist", [0.0] * 5)
        if not isinstance(dist, list) or len(dist) != 5 or not all(_is_number(v) and abs(v) < 100 for v in dist):
            raise BadCameraError(f"{where}.dist must be 5 numbers (k1 k2 p1 p2 k3)", field=f"{where}.dist")
        T = rigid_transform(c.get("T_world_cam"), f"{where}.T_world_cam")
        sigma = c.get("pixel_sigma", 0.25)
        if not _is_number(sigma) or not 0 < sigma <= 10:
            raise NoiseOutOfRangeError(
                f"{where}.pixel_sigma = {sigma} px is out of range (0, 10]", field=f"{where}.pixel_sigma"
            )
        out.append(RigCamera(cid, w, h, K, np.array(dist, float), T[:3, :3], T[:3, 3], float(sigma)))
    return out


def _tags(value: Any, limits: MarkerPoseLimits) -> tuple[str, float, list[int], FloatArray]:
    if not isinstance(value, dict):
        raise MalformedInputError("tags must be {family, size_m, layout: [{id, T_body_tag}]}", field="tags")
    extra = sorted(set(value) - {"family", "size_m", "layout"})
    if extra:
        raise UnknownFieldError(f"unknown field tags.{extra[0]}", field=f"tags.{extra[0]}")
    family = value.get("family")
    if family not in FAMILIES:
        raise UnknownFamilyError(f"tags.family {family!r} is not one of {', '.join(FAMILIES)}", field="tags.family")
    size: Any = value.get("size_m")
    if not _is_number(size) or not 0 < size <= 10:
        raise MalformedInputError(f"tags.size_m must be in (0, 10] m, not {size!r}", field="tags.size_m")
    layout = value.get("layout")
    if not isinstance(layout, list) or not layout:
        raise MalformedInputError("tags.layout must be a non-empty list", field="tags.layout")
    if len(layout) > limits.max_layout_markers:
        raise LimitExceededError(f"{len(layout)} tags; the limit is {limits.max_layout_markers}", field="tags.layout")
    ids: list[int] = []
    Ts = []
    for i, t in enumerate(layout):
        where = f"tags.layout[{i}]"
        tid = t.get("id") if isinstance(t, dict) else None
        if not isinstance(tid, int) or isinstance(tid, bool) or tid < 0:
            raise MalformedInputError(f"{where}.id must be an integer >= 0", field=f"{where}.id")
        if tid in ids:
            raise MalformedInputError(f"tag id {tid} appears twice", field=f"{where}.id")
        ids.append(tid)
        Ts.append(rigid_transform(t.get("T_body_tag"), f"{where}.T_body_tag"))
    T_body_tag = np.array(Ts)
    extent = float(np.max(np.linalg.norm(T_body_tag[:, None, :3, 3] - T_body_tag[None, :, :3, 3], axis=-1)))
    if extent > 10.0:
        raise MalformedInputError(
            f"the tags span {extent:.1f} m; over 10 m (millimetres sent as metres?)", field="tags.layout"
        )
    return family, float(size), ids, T_body_tag


def _frames(value: Any, limits: MarkerPoseLimits) -> dict[int, float]:
    if not isinstance(value, list) or not value:
        raise MalformedInputError("frames must be a non-empty list of {frame, t}", field="frames")
    if len(value) > limits.max_frames:
        raise LimitExceededError(f"{len(value)} frames; the limit is {limits.max_frames}", field="frames")
    out: dict[int, float] = {}
    for i, f in enumerate(value):
        if not isinstance(f, dict) or set(f) != {"frame", "t"}:
            raise MalformedInputError(f"frames[{i}] must be {{frame, t}}", field=f"frames[{i}]")
        n, t = f["frame"], f["t"]
        if not is_frame_number(n) or not _is_number(t):
            raise MalformedInputError(
                f"frames[{i}] needs an integer frame in [0, 2^53) and a time t", field=f"frames[{i}]"
            )
        if n in out:
            raise DuplicateObservationError(f"frame {n} is listed twice", field=f"frames[{i}].frame")
        out[n] = float(t)
    order = sorted(out)
    times = np.array([out[n] for n in order])
    if np.any(np.diff(times) <= 0):
        raise TimeOrderError("frames: t does not increase with frame", field="frames")
    return out


def _detections(dets: list[Any], out: TagInput, frame_t: dict[int, float] | None, limits: MarkerPoseLimits) -> None:
    if len(dets) > limits.max_observations:
        raise LimitExceededError(f"{len(dets)} detections; the limit is {limits.max_observations}", field="detections")
    cam_index = {c.id: i for i, c in enumerate(out.cameras)}
    tag_index = {t: i for i, t in enumerate(out.tag_ids)}
    n = len(dets)
    frame = np.empty(n, dtype=np.int64)
    t = np.empty(n)
    cam = np.empty(n, dtype=np.int64)
    tag = np.empty(n, dtype=np.int64)
    corners = np.empty((n, 4, 2))
    unknown_ids: set[int] = set()
    for i, d in enumerate(dets):
        where = f"detections[{i}]"
        if not isinstance(d, dict):
            raise MalformedInputError(f"{where} must be an object", field=where)
        extra = sorted(set(d) - DETECTION_KEYS)
        if extra:
            raise UnknownFieldError(f"unknown field {where}.{extra[0]}", field=f"{where}.{extra[0]}")
        f, ti, c, tid = d.get("frame"), d.get("t"), d.get("camera"), d.get("id")
        if not is_frame_number(f):
            raise MalformedInputError(f"{where}.frame must be an integer in [0, 2^53)", field=f"{where}.frame")
        if ti is None and frame_t is not None and f in frame_t:
            ti = frame_t[f]
        if not _is_number(ti):
            raise MalformedInputError(f"{where}.t must be a number [s]", field=f"{where}.t")
        if frame_t is not None and (f not in frame_t or frame_t[f] != ti):
            raise MalformedInputError(f"{where}: frame {f} at t = {ti} is not in frames", field=f"{where}.frame")
        if not isinstance(c, str) or c not in cam_index:
            raise MalformedInputError(f"{where}.camera {c!r} is not one of the cameras", field=f"{where}.camera")
        if not isinstance(tid, int) or isinstance(tid, bool):
            raise MalformedInputError(f"{where}.id must be an integer", field=f"{where}.id")
        uv = d.get("corners_px")
        if not (
            isinstance(uv, list)
            and len(uv) == 4
            and all(isinstance(p, list) and len(p) == 2 and all(_is_number(v) for v in p) for p in uv)
        ):
            raise BadCornersError(f"{where}.corners_px must be 4 [u, v] pairs", field=f"{where}.corners_px")
        camera = out.cameras[cam_index[c]]
        arr = np.array(uv, dtype=float)
        if (
            np.any(arr < -0.5)
            or np.any(arr[:, 0] > camera.width_px - 0.5)
            or np.any(arr[:, 1] > camera.height_px - 0.5)
        ):
            raise BadCornersError(
                f"{where}.corners_px lies outside the {camera.width_px}x{camera.height_px} image of {c}",
                field=f"{where}.corners_px",
            )
        frame[i], t[i], cam[i], corners[i] = f, ti, cam_index[c], arr
        if tid not in tag_index:
            unknown_ids.add(tid)
            tag[i] = -1
        else:
            tag[i] = tag_index[tid]
    if unknown_ids:
        out.warnings.append(f"detections of tag ids not in the layout were ignored: {sorted(unknown_ids)[:20]}")
    order = np.lexsort((tag, cam, frame))
    same = (
        (np.diff(frame[order]) == 0) & (np.diff(cam[order]) == 0) & (np.diff(tag[order]) == 0) & (tag[order][1:] >= 0)
    )
    if np.any(same):
        i = int(order[np.flatnonzero(same)[0] + 1])
        raise DuplicateObservationError(
            f"detections[{i}] repeats a (frame, camera, id) triple", field=f"detections[{i}]"
        )
    if frame_t is None:
        step = np.diff(frame[order]) > 0
        dt = np.diff(t[order])
        bad = (step & (dt <= 0)) | (~step & (dt != 0))
        if np.any(bad):
            i = int(order[np.flatnonzero(bad)[0] + 1])
            raise TimeOrderError(f"detections[{i}].t does not increase with frame", field=f"detections[{i}].t")
        frames, first = np.unique(frame, return_index=True)
        out.frames, out.t_s = frames.astype(np.int64), t[first]
    keep = order[tag[order] >= 0]
    out.det_frame = np.searchsorted(out.frames, frame[keep]).astype(np.int64)
    out.det_cam, out.det_tag, out.corners_px = cam[keep], tag[keep], corners[keep]
    if len(out.frames) > limits.max_frames:
        raise LimitExceededError(f"{len(out.frames)} frames; the limit is {limits.max_frames}", field="detections")
    if len(np.unique(out.det_frame)) < 3:
        raise TooFewFramesError(
            f"{len(np.unique(out.det_frame))} frames have a detection of a known tag; at least 3 are needed",
            field="detections",
        )
