"""Reading and validating level-A input: marker coordinates per frame and track (JSON
``tumblescan.markers.v1`` or CSV ``frame,t,track,x,y,z[,marker]``), and an optional layout.

Everything is checked once here, at the door; the estimator trusts what this returns.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeGuard

import numpy as np

from .._typing import FloatArray, IntArray
from ..io.json_text import parse_json
from .errors import (
    DegenerateLayoutError,
    DuplicateMarkerIdError,
    DuplicateObservationError,
    LayoutScaleError,
    LimitExceededError,
    MalformedInputError,
    NoiseOutOfRangeError,
    NonFiniteValueError,
    OutOfVolumeError,
    TimeOrderError,
    TooFewFramesError,
    UnknownFieldError,
    UnsupportedUnitsError,
)
from .options import MarkerPoseLimits

FORMAT = "tumblescan.markers.v1"
DEFAULT_SIGMA_M = 0.003
TOP_KEYS = {"format", "units", "frame", "frame_rate_hz", "sensor", "body", "observations"}
OBS_KEYS = {"frame", "t", "track", "xyz", "marker"}
CSV_HEADER = ["frame", "t", "track", "x", "y", "z"]


@dataclass
class Layout:
    """Marker ids and their body coordinates [m] (M, 3): they define the body frame."""

    ids: list[str]
    p_body_m: FloatArray
    warnings: list[str] = field(default_factory=list)


@dataclass
class MarkerInput:
    """Validated observations, sorted by frame then track.

    frames (F,): frame numbers, increasing; t_s (F,): their times; obs_frame (N,): index into
    ``frames``; obs_track (N,): index into ``track_names``; xyz_m (N, 3): world coordinates;
    obs_label (N,): index into ``label_names`` of the tracker's label (-1: none)."""

    frames: IntArray
    t_s: FloatArray
    obs_frame: IntArray
    obs_track: IntArray
    xyz_m: FloatArray
    obs_label: IntArray
    track_names: list[str]
    label_names: list[str]
    layout: Layout | None
    point_sigma_m: float
    frame_rate_hz: float | None
    warnings: list[str] = field(default_factory=list)

    @property
    def n_frames(self) -> int:
        return len(self.frames)


def sniff(path: Path, field: str = "markers") -> str:
    """'json' or 'csv' from the first bytes (names are not trusted)."""
    with open(path, "rb") as fh:
        head = fh.read(256).lstrip()
    if head.startswith(b"{"):
        return "json"
    if head.lower().startswith(b"frame"):
        return "csv"
    raise MalformedInputError(
        f"{field} must be JSON (tumblescan.markers.v1) or CSV with a header frame,t,track,x,y,z", field=field
    )


def read_markers(
    path: Path,
    *,
    layout_path: Path | None = None,
    point_sigma_m: float | None = None,
    limits: MarkerPoseLimits | None = None,
) -> MarkerInput:
    """Read a markers file (JSON or CSV, sniffed) and an optional layout file, and validate them."""
    limits = limits or MarkerPoseLimits()
    if sniff(path) == "json":
        doc = _load_json(path, "markers")
    else:
        doc = {"format": FORMAT, "observations": _csv_observations(path.read_text())}
    if layout_path is not None:
        layout_doc = _load_json(layout_path, "layout")
        if "body" in doc:
            raise MalformedInputError(
                "give the layout once: in the document's body or as the layout file", field="layout"
            )
        doc["body"] = layout_doc.get("body", layout_doc) if isinstance(layout_doc, dict) else layout_doc
    return markers_from_json(doc, point_sigma_m=point_sigma_m, limits=limits)


def _load_json(path: Path, name: str) -> Any:
    return parse_json(path.read_bytes(), name, error=MalformedInputError)


def _csv_observations(text: str) -> list[dict[str, Any]]:
    rows = csv.reader(io.StringIO(text))
    header = [h.strip() for h in next(rows, [])]
    if header[:6] != CSV_HEADER or len(header) > 7 or (len(header) == 7 and header[6] != "marker"):
        raise MalformedInputError("CSV header must be frame,t,track,x,y,z[,marker]", field="markers")
    out: list[dict[str, Any]] = []
    for line, row in enumerate(rows, start=2):
        if not row:
            continue
        if len(row) != len(header):
            raise MalformedInputError(f"CSV line {line} has {len(row)} values, not {len(header)}", field="markers")
        try:
            o: dict[str, Any] = {
                "frame": int(row[0]),
                "t": float(row[1]),
                "track": row[2].strip(),
                "xyz": [float(row[3]), float(row[4]), float(row[5])],
            }
        except ValueError as exc:
            raise MalformedInputError(f"CSV line {line}: {exc}", field="markers") from None
        if len(row) == 7 and row[6].strip():
            o["marker"] = row[6].strip()
        out.append(o)
    return out


def markers_from_json(
    doc: Any, *, point_sigma_m: float | None = None, limits: MarkerPoseLimits | None = None
) -> MarkerInput:
    """Validate a ``tumblescan.markers.v1`` document; every refusal names its field."""
    limits = limits or MarkerPoseLimits()
    if not isinstance(doc, dict):
        raise MalformedInputError("the markers document must be a JSON object", field="input")
    unknown = sorted(set(doc) - TOP_KEYS)
    if unknown:
        raise UnknownFieldError(f"unknown field {unknown[0]!r}", field=unknown[0])
    if doc.get("format", FORMAT) != FORMAT:
        raise MalformedInputError(f"format must be {FORMAT!r}, not {doc.get('format')!r}", field="format")
    warnings: list[str] = []
    _check_units(doc.get("units"))
    rate = doc.get("frame_rate_hz")
    if rate is not None and (not _is_number(rate) or not math.isfinite(rate) or rate <= 0):
        raise NonFiniteValueError("frame_rate_hz must be a positive number", field="frame_rate_hz")
    sigma = _sigma(doc.get("sensor"), point_sigma_m, warnings)
    layout = None
    if doc.get("body") is not None:
        layout = layout_from_json(doc["body"], limits)
        warnings += layout.warnings
    obs = doc.get("observations")
    if not isinstance(obs, list) or not obs:
        raise MalformedInputError("observations must be a non-empty list", field="observations")
    if len(obs) > limits.max_observations:
        raise LimitExceededError(
            f"{len(obs)} observations; the limit is {limits.max_observations}", field="observations"
        )
    return _observations(obs, layout, sigma, float(rate) if rate is not None else None, limits, warnings)


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


# The largest integer JSON (a double) carries exactly; frame numbers are stored as int64.
MAX_FRAME_NUMBER = 2**53 - 1


def is_frame_number(v: Any) -> TypeGuard[int]:
    """An integer frame number in [0, MAX_FRAME_NUMBER]."""
    return isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= MAX_FRAME_NUMBER


def _check_units(units: Any) -> None:
    if units is None:
        return
    if not isinstance(units, dict):
        raise MalformedInputError('units must be {"length": "m", "time": "s"}', field="units")
    for key, want in (("length", "m"), ("time", "s")):
        if units.get(key, want) != want:
            raise UnsupportedUnitsError(
                f"units.{key} must be {want!r}, not {units.get(key)!r} (convert before sending)", field=f"units.{key}"
            )
    extra = sorted(set(units) - {"length", "time"})
    if extra:
        raise UnknownFieldError(f"unknown field units.{extra[0]}", field=f"units.{extra[0]}")


def _sigma(sensor: Any, override: float | None, warnings: list[str]) -> float:
    field_name = "options.point_sigma_m" if override is not None else "sensor.point_sigma_m"
    value: Any = override
    if value is None:
        if sensor is not None and not isinstance(sensor, dict):
            raise MalformedInputError("sensor must be an object", field="sensor")
        value = (sensor or {}).get("point_sigma_m")
    if value is None:
        warnings.append(f"sensor.point_sigma_m not given: {DEFAULT_SIGMA_M * 1000:.0f} mm assumed")
        return DEFAULT_SIGMA_M
    if not _is_number(value) or not math.isfinite(value):
        raise NonFiniteValueError(f"{field_name} must be a finite number", field=field_name)
    if value <= 0 or value > 0.1:
        raise NoiseOutOfRangeError(
            f"{field_name} = {value} m is out of range (0, 0.1] (millimetres sent as metres?)", field=field_name
        )
    return float(value)


def layout_from_json(body: Any, limits: MarkerPoseLimits | None = None) -> Layout:
    """``{"markers": [{"id", "xyz"}]}``: at least 3 markers, unique ids, not collinear, under 10 m."""
    limits = limits or MarkerPoseLimits()
    markers = body.get("markers") if isinstance(body, dict) else None
    if not isinstance(markers, list):
        raise MalformedInputError('body must be {"markers": [{"id": ..., "xyz": [x, y, z]}]}', field="body.markers")
    if len(markers) > limits.max_layout_markers:
        raise LimitExceededError(
            f"{len(markers)} layout markers; the limit is {limits.max_layout_markers}", field="body.markers"
        )
    if len(markers) < 3:
        raise DegenerateLayoutError(f"the layout needs at least 3 markers, got {len(markers)}", field="body.markers")
    ids: list[str] = []
    xyz: list[list[float]] = []
    for i, m in enumerate(markers):
        where = f"body.markers[{i}]"
        if not isinstance(m, dict) or not isinstance(m.get("id"), str) or not m["id"]:
            raise MalformedInputError(f"{where} needs a non-empty string id", field=f"{where}.id")
        p = m.get("xyz")
        if not isinstance(p, list) or len(p) != 3 or not all(_is_number(v) for v in p):
            raise MalformedInputError(f"{where}.xyz must be 3 numbers", field=f"{where}.xyz")
        if not all(math.isfinite(v) for v in p):
            raise NonFiniteValueError(f"{where}.xyz is not finite", field=f"{where}.xyz")
        if m["id"] in ids:
            raise DuplicateMarkerIdError(f"marker id {m['id']!r} appears twice", field=f"{where}.id")
        ids.append(m["id"])
        xyz.append([float(v) for v in p])
    p_m = np.array(xyz)
    extent = float(np.max(np.linalg.norm(p_m[:, None] - p_m[None], axis=-1)))
    if extent > 10.0:
        raise LayoutScaleError(
            f"the layout spans {extent:.1f} m; over 10 m (millimetres sent as metres?)", field="body.markers"
        )
    s = np.linalg.svd(p_m - p_m.mean(axis=0), compute_uv=False)
    if extent < 1e-3 or s[1] < 1e-3 * max(extent, 1e-9) or s[1] < 1e-4:
        raise DegenerateLayoutError("the layout's markers are collinear (or coincide)", field="body.markers")
    layout = Layout(ids, p_m)
    if symmetric_layout(p_m, tol_m=0.004):
        layout.warnings.append(
            "the layout is (nearly) symmetric: markers cannot be told apart by their distances; "
            "identities rely on tracks"
        )
    return layout


def symmetric_layout(p_m: FloatArray, tol_m: float) -> bool:
    """Whether a relabelling other than the identity keeps every pairwise distance within ``tol_m``."""
    from itertools import permutations

    M = len(p_m)
    d = np.linalg.norm(p_m[:, None] - p_m[None], axis=-1)
    if M > 8:  # too many relabellings to try; pairwise gaps tell the same story
        gaps = np.diff(np.sort(d[np.triu_indices(M, 1)]))
        return bool(np.min(gaps) < tol_m)
    ident = tuple(range(M))
    return any(perm != ident and np.max(np.abs(d[np.ix_(perm, perm)] - d)) < tol_m for perm in permutations(range(M)))


def _observations(
    obs: list[Any],
    layout: Layout | None,
    sigma: float,
    rate: float | None,
    limits: MarkerPoseLimits,
    warnings: list[str],
) -> MarkerInput:
    n = len(obs)
    frame = np.empty(n, dtype=np.int64)
    t = np.empty(n)
    xyz = np.empty((n, 3))
    tracks: dict[str, int] = {}
    labels: dict[str, int] = {}
    track = np.empty(n, dtype=np.int64)
    label = np.full(n, -1, dtype=np.int64)
    for i, o in enumerate(obs):
        if not isinstance(o, dict):
            raise MalformedInputError(f"observations[{i}] must be an object", field=f"observations[{i}]")
        extra = set(o) - OBS_KEYS
        if extra:
            key = sorted(extra)[0]
            raise UnknownFieldError(f"unknown field observations[{i}].{key}", field=f"observations[{i}].{key}")
        f, ti, tr, p = o.get("frame"), o.get("t"), o.get("track"), o.get("xyz")
        if not is_frame_number(f):
            raise MalformedInputError(
                f"observations[{i}].frame must be an integer in [0, 2^53)", field=f"observations[{i}].frame"
            )
        if not _is_number(ti):
            raise MalformedInputError(f"observations[{i}].t must be a number [s]", field=f"observations[{i}].t")
        if isinstance(tr, int) and not isinstance(tr, bool):
            tr = str(tr)
        if not isinstance(tr, str) or not tr:
            raise MalformedInputError(
                f"observations[{i}].track must be a non-empty string", field=f"observations[{i}].track"
            )
        if not isinstance(p, list) or len(p) != 3 or not all(_is_number(v) for v in p):
            raise MalformedInputError(f"observations[{i}].xyz must be 3 numbers [m]", field=f"observations[{i}].xyz")
        frame[i], t[i], xyz[i] = f, ti, p
        track[i] = tracks.setdefault(tr, len(tracks))
        if o.get("marker") is not None:
            if not isinstance(o["marker"], str):
                raise MalformedInputError(
                    f"observations[{i}].marker must be a string", field=f"observations[{i}].marker"
                )
            label[i] = labels.setdefault(o["marker"], len(labels))
    _check_values(frame, t, xyz, track, limits, len(tracks))
    order = np.lexsort((track, frame))
    frame, t, xyz, track, label = frame[order], t[order], xyz[order], track[order], label[order]
    _check_order(frame, t, track, order)
    frames, obs_frame = np.unique(frame, return_inverse=True)
    t_s = t[np.r_[0, np.flatnonzero(np.diff(frame)) + 1]]
    counts = np.bincount(obs_frame)
    if int(np.sum(counts >= 3)) < 3:
        raise TooFewFramesError(
            f"{int(np.sum(counts >= 3))} frames have 3 or more markers; at least 3 are needed", field="observations"
        )
    if len(frames) > limits.max_frames:
        raise LimitExceededError(f"{len(frames)} frames; the limit is {limits.max_frames}", field="observations")
    return MarkerInput(
        frames=frames.astype(np.int64),
        t_s=t_s,
        obs_frame=obs_frame.astype(np.int64),
        obs_track=track,
        xyz_m=xyz,
        obs_label=label,
        track_names=list(tracks),
        label_names=list(labels),
        layout=layout,
        point_sigma_m=sigma,
        frame_rate_hz=rate,
        warnings=warnings,
    )


def _check_values(
    frame: IntArray, t: FloatArray, xyz: FloatArray, track: IntArray, limits: MarkerPoseLimits, n_tracks: int
) -> None:
    bad_t = np.flatnonzero(~np.isfinite(t))
    if len(bad_t):
        raise NonFiniteValueError(f"observations[{bad_t[0]}].t is not finite", field=f"observations[{bad_t[0]}].t")
    bad = np.flatnonzero(~np.all(np.isfinite(xyz), axis=1))
    if len(bad):
        raise NonFiniteValueError(f"observations[{bad[0]}].xyz is not finite", field=f"observations[{bad[0]}].xyz")
    far = np.flatnonzero(np.linalg.norm(xyz, axis=1) > limits.max_range_m)
    if len(far):
        i = int(far[0])
        raise OutOfVolumeError(
            f"observations[{i}].xyz is {np.linalg.norm(xyz[i]):.0f} m from the origin, beyond "
            f"{limits.max_range_m:.0f} m (millimetres sent as metres?)",
            field=f"observations[{i}].xyz",
        )
    if n_tracks > limits.max_tracks:
        raise LimitExceededError(f"{n_tracks} tracks; the limit is {limits.max_tracks}", field="observations")


def _check_order(frame: IntArray, t: FloatArray, track: IntArray, order: IntArray) -> None:
    same = (np.diff(frame) == 0) & (np.diff(track) == 0)
    if np.any(same):
        i = int(order[np.flatnonzero(same)[0] + 1])
        raise DuplicateObservationError(
            f"observations[{i}] repeats a (frame, track) pair: one observation per track per frame",
            field=f"observations[{i}]",
        )
    step = np.diff(frame) > 0
    dt = np.diff(t)
    within = ~step & (dt != 0)
    if np.any(within):
        i = int(order[np.flatnonzero(within)[0] + 1])
        raise TimeOrderError(
            f"observations[{i}].t differs from its frame's other observations", field=f"observations[{i}].t"
        )
    across = step & (dt <= 0)
    if np.any(across):
        i = int(order[np.flatnonzero(across)[0] + 1])
        raise TimeOrderError(f"observations[{i}].t does not increase with frame", field=f"observations[{i}].t")
