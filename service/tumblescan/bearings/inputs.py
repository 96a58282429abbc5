"""Reading and validating ``tumblescan.bearings.input/1`` (validated once, here, at the door).

Every refusal is an ``InvalidBearingsInputError`` (code ``invalid_input``) whose message starts
with the JSON path of the field at fault, e.g. ``frames[3].detections.S1[2].el_deg``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict

from .._typing import FloatArray
from ..io.json_text import parse_json
from .errors import InvalidBearingsInputError, TooLargeError
from .geometry import R_ecef_from_enu, Station, geodetic_to_ecef

INPUT_SCHEMA = "tumblescan.bearings.input/1"
UNITS = {"angle": "deg", "length": "m", "time": "s"}
# Frame times are seconds from the input's epoch; beyond these the tracker's predictions lose all
# precision (and overflow), so such times are refused at the door rather than half-processed.
MAX_ABS_TIME_S = 1e10  # about 317 years either side of the epoch
MIN_FRAME_STEP_S = 1e-6  # two exposures closer than a microsecond are not distinct frames
MAX_LOCAL_COORD_M = 1e7  # a local ENU frame tangent to the Earth is meaningless much beyond this
MAX_POSITION_SIGMA_M = 1e4
MIN_SIGMA_DEG = 1e-9  # 3.6 micro-arcseconds: below any sensor, and far enough from 0 that 1/σ² stays finite
JobFrame = Literal["local_enu", "ecef"]


class Limits(BaseModel):
    """Input sizes a job accepts (beyond them: ``too_large``, HTTP 413)."""

    model_config = ConfigDict(extra="forbid")
    max_detections_per_station_frame: int = 10_000
    max_detections_total: int = 2_000_000
    max_input_bytes: int = 400_000_000


@dataclass(frozen=True)
class Detections:
    """One station's detections in one frame (angles in rad, in the station's own ENU)."""

    ids: list[str]
    az_rad: FloatArray
    el_rad: FloatArray
    sigma_az_rad: FloatArray
    sigma_el_rad: FloatArray
    snr: FloatArray  # NaN where not given

    def __len__(self) -> int:
        return len(self.ids)


@dataclass(frozen=True)
class Frame:
    index: int
    t_s: float
    detections: tuple[Detections, Detections]


@dataclass(frozen=True)
class BearingsInput:
    frame: JobFrame
    stations: tuple[Station, Station]
    frames: list[Frame]
    epoch_utc: str | None = None

    @property
    def n_detections(self) -> int:
        return sum(len(d) for f in self.frames for d in f.detections)


class _NonFinite:
    """A NaN or ±Infinity JSON token, kept so that validation can name its field."""

    def __init__(self, token: str) -> None:
        self.token = token

    def __repr__(self) -> str:
        return self.token


def _bad(field: str, message: str) -> InvalidBearingsInputError:
    return InvalidBearingsInputError(f"{field} {message}", field=field)


def _number(value: Any, field: str) -> float:
    if isinstance(value, _NonFinite):
        raise _bad(field, f"= {value!r} is not a finite number")
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise _bad(field, f"= {json.dumps(value, default=repr)[:40]} is not a number")
    x = float(value)
    if not math.isfinite(x):
        raise _bad(field, f"= {x} is not a finite number")
    return x


def _sigma_deg(value: Any, field: str) -> float:
    x = _number(value, field)
    if not MIN_SIGMA_DEG <= x < 5.0:
        raise _bad(field, f"= {x:g} must be >= {MIN_SIGMA_DEG:g} and < 5 degrees")
    return x


def _obj(value: Any, field: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise _bad(field, "must be a JSON object")
    return value


def _list(value: Any, field: str) -> list[Any]:
    if not isinstance(value, list):
        raise _bad(field, "must be a JSON array")
    return value


TOP_FIELDS = frozenset({"schema", "frame", "units", "epoch_utc", "stations", "frames"})
STATION_FIELDS = frozenset({"id", "sigma_az_deg", "sigma_el_deg", "position_m", "position_sigma_m", "geodetic"})
GEODETIC_FIELDS = frozenset({"lat_deg", "lon_deg", "height_m"})
FRAME_FIELDS = frozenset({"index", "t", "detections"})
DETECTION_FIELDS = frozenset({"id", "az_deg", "el_deg", "snr", "sigma_az_deg", "sigma_el_deg"})


def _known(obj: dict[str, Any], fields: frozenset[str], where: str) -> None:
    """Refuse a field the format does not have: a misspelt ``sigma_az_deg`` override would
    otherwise be ignored and the station's σ used in its place, silently."""
    unknown = sorted(set(obj) - fields)
    if unknown:
        name = f"{where}.{unknown[0]}" if where else unknown[0]
        raise _bad(name, f"is not a field of the input (known: {', '.join(sorted(fields))})")


def load_json(data: bytes | str, *, field: str = "input") -> Any:
    """Parse JSON, keeping NaN/Infinity tokens for validation to name."""
    return parse_json(data, field, error=InvalidBearingsInputError, parse_constant=_NonFinite)


def read_input(path: Path, limits: Limits | None = None) -> BearingsInput:
    """Read and validate an input file."""
    limits = limits or Limits()
    size = path.stat().st_size
    if size > limits.max_input_bytes:
        raise TooLargeError(f"{path.name} has {size} bytes; the limit is {limits.max_input_bytes}", field="input")
    return parse_input(load_json(path.read_bytes()), limits)


def parse_input(doc: Any, limits: Limits | None = None) -> BearingsInput:
    """Validate a parsed input document (see the digest's §6.1) and convert it to arrays."""
    limits = limits or Limits()
    doc = _obj(doc, "input")
    _known(doc, TOP_FIELDS, "")
    if doc.get("schema") != INPUT_SCHEMA:
        raise _bad("schema", f"= {json.dumps(doc.get('schema'), default=repr)} is not {INPUT_SCHEMA!r}")
    frame = doc.get("frame")
    if frame not in ("local_enu", "ecef"):
        raise _bad("frame", f"= {json.dumps(frame, default=repr)} is not 'local_enu' or 'ecef'")
    if "units" in doc and doc["units"] != UNITS:
        raise _bad("units", f"= {json.dumps(doc['units'], default=repr)} must be exactly {json.dumps(UNITS)}")
    epoch = doc.get("epoch_utc")
    if epoch is not None and not isinstance(epoch, str):
        raise _bad("epoch_utc", "must be a string")
    stations = _stations(doc.get("stations"), frame)
    frames = _frames(doc.get("frames"), stations, limits)
    return BearingsInput(frame=frame, stations=stations, frames=frames, epoch_utc=epoch)


def _stations(value: Any, frame: JobFrame) -> tuple[Station, Station]:
    items = _list(value, "stations")
    if len(items) != 2:
        raise _bad("stations", f"has {len(items)} entries; exactly 2 stations are needed")
    out = []
    for i, raw in enumerate(items):
        f = f"stations[{i}]"
        st = _obj(raw, f)
        _known(st, STATION_FIELDS, f)
        sid = st.get("id")
        if not isinstance(sid, str) or not sid:
            raise _bad(f"{f}.id", "must be a non-empty string")
        for key in ("sigma_az_deg", "sigma_el_deg"):
            if key not in st:
                raise _bad(f"{f}.{key}", "is missing (the 1-sigma angle error in degrees)")
        sa = _sigma_deg(st["sigma_az_deg"], f"{f}.sigma_az_deg")
        se = _sigma_deg(st["sigma_el_deg"], f"{f}.sigma_el_deg")
        ps = _number(st.get("position_sigma_m", 0.0), f"{f}.position_sigma_m")
        if not 0.0 <= ps <= MAX_POSITION_SIGMA_M:
            raise _bad(f"{f}.position_sigma_m", f"= {ps:g} must be >= 0 and <= {MAX_POSITION_SIGMA_M:g} m")
        geodetic = None
        if frame == "local_enu":
            if "position_m" not in st:
                raise _bad(f"{f}.position_m", "is missing (needed for frame 'local_enu')")
            pos = _list(st["position_m"], f"{f}.position_m")
            if len(pos) != 3:
                raise _bad(f"{f}.position_m", "must be [x, y, z] in metres")
            p = np.array([_number(v, f"{f}.position_m[{k}]") for k, v in enumerate(pos)])
            if np.abs(p).max() > MAX_LOCAL_COORD_M:
                too_far = f"has a coordinate over {MAX_LOCAL_COORD_M:g} m (too far for a local frame)"
                raise _bad(f"{f}.position_m", too_far)
            R = np.eye(3)
        else:
            if "geodetic" not in st:
                raise _bad(f"{f}.geodetic", "is missing (needed for frame 'ecef')")
            g = _obj(st["geodetic"], f"{f}.geodetic")
            _known(g, GEODETIC_FIELDS, f"{f}.geodetic")
            for key in ("lat_deg", "lon_deg", "height_m"):
                if key not in g:
                    raise _bad(f"{f}.geodetic.{key}", "is missing")
            lat = _number(g["lat_deg"], f"{f}.geodetic.lat_deg")
            lon = _number(g["lon_deg"], f"{f}.geodetic.lon_deg")
            h = _number(g["height_m"], f"{f}.geodetic.height_m")
            if not -90.0 <= lat <= 90.0:
                raise _bad(f"{f}.geodetic.lat_deg", f"= {lat:g} is outside [-90, 90]")
            if not -180.0 <= lon <= 360.0:
                raise _bad(f"{f}.geodetic.lon_deg", f"= {lon:g} is outside [-180, 360]")
            if not -12_000.0 <= h <= 100_000.0:
                raise _bad(f"{f}.geodetic.height_m", f"= {h:g} is outside [-12000, 100000] m")
            p, R, geodetic = geodetic_to_ecef(lat, lon, h), R_ecef_from_enu(lat, lon), (lat, lon, h)
        out.append(Station(sid, p, R, np.radians(sa), np.radians(se), ps, geodetic))
    if out[0].id == out[1].id:
        raise _bad("stations[1].id", f"= {out[0].id!r} duplicates stations[0].id")
    baseline = float(np.linalg.norm(out[1].p_job_m - out[0].p_job_m))
    if baseline < 1.0:
        raise _bad("stations", f"are {baseline:.3g} m apart; a baseline of at least 1 m is needed")
    return out[0], out[1]


def _frames(value: Any, stations: tuple[Station, Station], limits: Limits) -> list[Frame]:
    items = _list(value, "frames")
    if not items:
        raise _bad("frames", "is empty; at least one frame is needed")
    ids_seen: set[str] = set()
    indices: set[int] = set()
    frames: list[Frame] = []
    total = 0
    last_t = -math.inf
    names = (stations[0].id, stations[1].id)
    for fi, raw in enumerate(items):
        f = f"frames[{fi}]"
        fr = _obj(raw, f)
        _known(fr, FRAME_FIELDS, f)
        index = fr.get("index")
        if isinstance(index, bool) or not isinstance(index, int):
            raise _bad(f"{f}.index", "must be an integer")
        if index in indices:
            raise _bad(f"{f}.index", f"= {index} duplicates an earlier frame index")
        indices.add(index)
        if "t" not in fr:
            raise _bad(f"{f}.t", "is missing (seconds)")
        t = _number(fr["t"], f"{f}.t")
        if abs(t) > MAX_ABS_TIME_S:
            raise _bad(f"{f}.t", f"= {t:g} s is over {MAX_ABS_TIME_S:g} s from the epoch; give times relative to it")
        if t <= last_t:
            raise _bad(f"{f}.t", f"= {t:g} is not after the previous frame's {last_t:g} (t must strictly increase)")
        if t - last_t < MIN_FRAME_STEP_S:
            raise _bad(f"{f}.t", f"= {t:g} is less than {MIN_FRAME_STEP_S:g} s after the previous frame's {last_t:g}")
        last_t = t
        dets = _obj(fr.get("detections", {}), f"{f}.detections")
        for key in dets:
            if key not in names:
                raise _bad(f"{f}.detections.{key}", f"is not a station id (stations are {names[0]!r}, {names[1]!r})")
        per_station = []
        for st in stations:
            d = _detections(dets.get(st.id, []), f"{f}.detections.{st.id}", st, ids_seen, limits)
            total += len(d)
            per_station.append(d)
        if total > limits.max_detections_total:
            raise TooLargeError(
                f"{f} brings the input over {limits.max_detections_total} detections in total", field="frames"
            )
        frames.append(Frame(index=index, t_s=t, detections=(per_station[0], per_station[1])))
    return frames


def _detections(value: Any, f: str, station: Station, ids_seen: set[str], limits: Limits) -> Detections:
    items = _list(value, f)
    n = len(items)
    if n > limits.max_detections_per_station_frame:
        raise TooLargeError(
            f"{f} has {n} detections; the limit is {limits.max_detections_per_station_frame} per station and frame",
            field=f,
        )
    ids: list[str] = []
    arr = np.empty((n, 5))
    sa_default, se_default = np.degrees(station.sigma_az_rad), np.degrees(station.sigma_el_rad)
    for j, raw in enumerate(items):
        g = f"{f}[{j}]"
        det = _obj(raw, g)
        _known(det, DETECTION_FIELDS, g)
        did = det.get("id")
        if not isinstance(did, str) or not did:
            raise _bad(f"{g}.id", "must be a non-empty string")
        if did in ids_seen:
            raise _bad(f"{g}.id", f"= {did!r} duplicates an earlier detection id")
        ids_seen.add(did)
        ids.append(did)
        if "az_deg" not in det or "el_deg" not in det:
            raise _bad(f"{g}.{'az_deg' if 'az_deg' not in det else 'el_deg'}", "is missing")
        az = _number(det["az_deg"], f"{g}.az_deg")
        el = _number(det["el_deg"], f"{g}.el_deg")
        if not -90.0 <= el <= 90.0:
            raise _bad(f"{g}.el_deg", f"= {el:g} is outside [-90, 90]")
        sa = _sigma_deg(det["sigma_az_deg"], f"{g}.sigma_az_deg") if "sigma_az_deg" in det else sa_default
        se = _sigma_deg(det["sigma_el_deg"], f"{g}.sigma_el_deg") if "sigma_el_deg" in det else se_default
        snr = math.nan
        if "snr" in det:
            snr = _number(det["snr"], f"{g}.snr")
            if snr <= 0.0:
                raise _bad(f"{g}.snr", f"= {snr:g} must be > 0")
        arr[j] = (az, el, sa, se, snr)
    rad = np.radians(arr[:, :4])
    return Detections(ids, rad[:, 0], rad[:, 1], rad[:, 2], rad[:, 3], arr[:, 4])
