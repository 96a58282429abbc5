"""Tracks as JSON or CSV.

JSON: ``{"observations": [{"track": "c1", "t": 0.013, "xyz": [x, y, z]}, ...],
"sensor": {"range_sigma_m": 0.02, "angle_sigma_arcsec": 36}}`` (SI units; ``sensor`` and
a per-observation integer ``frame`` are optional). CSV: header ``track,t,x,y,z`` (an
optional ``frame`` column may follow). Anything else is an error naming the field.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ValidationError

from ..errors import MalformedInputError, NonFiniteValueError, UnknownFieldError
from ..io.json_text import parse_json
from .sensor import SensorNoise
from .tracks import Tracks

OBS_FIELDS = {"track", "t", "xyz", "frame"}
TOP_FIELDS = {"observations", "sensor"}
CSV_HEADER = ["track", "t", "x", "y", "z"]


def read_tracks(path: str | os.PathLike[str]) -> Tracks:
    """Read tracks from a ``.json`` or ``.csv`` file (by extension, else by content)."""
    p = Path(path)
    text = p.read_text(encoding="utf-8")
    if p.suffix.lower() == ".csv" or (p.suffix.lower() != ".json" and not text.lstrip().startswith("{")):
        return tracks_from_csv(text)
    return tracks_from_json(text)


def tracks_from_json(doc: str | bytes | dict[str, Any]) -> Tracks:
    """Parse and validate the tracks JSON (a string or an already-decoded object)."""
    obj = _decode(doc) if isinstance(doc, str | bytes) else doc
    if not isinstance(obj, dict):
        raise MalformedInputError("tracks JSON must be an object with 'observations'", field="tracks")
    unknown = sorted(set(obj) - TOP_FIELDS)
    if unknown:
        raise UnknownFieldError(f"unknown field(s) in tracks: {', '.join(unknown)}", field=unknown[0])
    obs = obj.get("observations")
    if not isinstance(obs, list) or not obs:
        raise MalformedInputError("'observations' must be a non-empty list", field="observations")
    names, times, xyz, frames = [], [], [], []
    has_frame = isinstance(obs[0], dict) and "frame" in obs[0]
    for i, o in enumerate(obs):
        name, t, p, f = _observation(i, o, has_frame)
        names.append(name)
        times.append(t)
        xyz.append(p)
        frames.append(f)
    sensor = _sensor(obj.get("sensor"))
    frame_idx = [int(f) for f in frames if f is not None] if has_frame else None
    return Tracks.from_arrays(names, times, xyz, frame=frame_idx, sensor=sensor)


def tracks_from_csv(text: str) -> Tracks:
    """Parse CSV with header ``track,t,x,y,z`` (optionally ``,frame``)."""
    reader = csv.reader(io.StringIO(text))
    header = [h.strip() for h in next(reader, [])]
    if header not in (CSV_HEADER, [*CSV_HEADER, "frame"]):
        raise MalformedInputError(
            f"CSV header must be 'track,t,x,y,z' (optionally ',frame'); got {','.join(header)!r}", field="header"
        )
    names, values, frames = [], [], []
    for row_no, row in enumerate(reader, start=2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise MalformedInputError(
                f"CSV line {row_no}: expected {len(header)} values, got {len(row)}", field=f"line {row_no}"
            )
        names.append(row[0].strip())
        try:
            values.append([float(c) for c in row[1:5]])
            if len(header) == 6:
                frames.append(int(row[5]))
        except ValueError:
            raise MalformedInputError(
                f"CSV line {row_no}: t, x, y, z must be numbers (frame an integer)", field=f"line {row_no}"
            ) from None
    if not names:
        raise MalformedInputError("CSV has no observations", field="observations")
    arr = np.array(values)
    return Tracks.from_arrays(names, arr[:, 0], arr[:, 1:4], frame=frames if len(header) == 6 else None)


def tracks_to_json(tracks: Tracks) -> dict[str, Any]:
    """The JSON object for ``tracks`` (frames included so they round-trip exactly)."""
    out: dict[str, Any] = {
        "observations": [
            {"track": tracks.track_ids[k], "t": float(t), "xyz": [float(v) for v in p], "frame": int(f)}
            for k, t, p, f in zip(tracks.track, tracks.t_s, tracks.xyz_m, tracks.frame, strict=True)
        ]
    }
    if tracks.sensor is not None:
        out["sensor"] = tracks.sensor.model_dump()
    return out


def write_tracks(path: str | os.PathLike[str], tracks: Tracks) -> None:
    p = Path(path)
    if p.suffix.lower() == ".csv":
        with open(p, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow([*CSV_HEADER, "frame"])
            for k, t, xyz, f in zip(tracks.track, tracks.t_s, tracks.xyz_m, tracks.frame, strict=True):
                w.writerow([tracks.track_ids[k], repr(float(t)), *(repr(float(v)) for v in xyz), int(f)])
    else:
        p.write_text(json.dumps(tracks_to_json(tracks)), encoding="utf-8")


def _decode(doc: str | bytes) -> Any:
    # NaN and Infinity literals parse to floats and are then rejected with their field.
    return parse_json(doc, "tracks", error=MalformedInputError)


def _observation(i: int, o: Any, has_frame: bool) -> tuple[str, float, list[float], int | None]:
    where = f"observations[{i}]"
    if not isinstance(o, dict):
        raise MalformedInputError(f"{where} must be an object", field=where)
    unknown = sorted(set(o) - OBS_FIELDS)
    if unknown:
        raise UnknownFieldError(f"{where}: unknown field(s) {', '.join(unknown)}", field=f"{where}.{unknown[0]}")
    missing = sorted({"track", "t", "xyz"} - set(o)) + (["frame"] if has_frame and "frame" not in o else [])
    if missing:
        raise MalformedInputError(f"{where}: missing {', '.join(missing)}", field=f"{where}.{missing[0]}")
    if "frame" in o and not has_frame:
        raise MalformedInputError(
            f"{where}.frame: give 'frame' for every observation or for none", field=f"{where}.frame"
        )
    track = o["track"]
    if not isinstance(track, str | int) or isinstance(track, bool) or str(track) == "":
        raise MalformedInputError(f"{where}.track must be a non-empty string", field=f"{where}.track")
    t = _number(o["t"], f"{where}.t")
    xyz = o["xyz"]
    if not isinstance(xyz, list) or len(xyz) != 3:
        raise MalformedInputError(f"{where}.xyz must be a list of 3 numbers", field=f"{where}.xyz")
    p = [_number(v, f"{where}.xyz") for v in xyz]
    frame = o.get("frame")
    if has_frame and (not isinstance(frame, int) or isinstance(frame, bool) or frame < 0):
        raise MalformedInputError(f"{where}.frame must be a non-negative integer", field=f"{where}.frame")
    return str(track), t, p, frame


def _number(v: Any, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise MalformedInputError(f"{where} must be a number", field=where)
    f = float(v)
    if not math.isfinite(f):
        raise NonFiniteValueError(f"{where} is not a finite number", field=where)
    return f


def _sensor(obj: Any) -> SensorNoise | None:
    if obj is None:
        return None
    try:
        return SensorNoise.model_validate(obj)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(p) for p in err["loc"])
        kind = UnknownFieldError if err["type"] == "extra_forbidden" else MalformedInputError
        raise kind(f"sensor.{loc}: {err['msg']}", field=f"sensor.{loc}") from None
