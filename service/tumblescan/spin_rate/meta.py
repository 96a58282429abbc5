"""The input contract ``tumblescan.spin_from_images.input/1``: meta.json, validated once at the door.

Every refusal is an ``InputError`` (code ``invalid_input``) whose ``field`` names the field at
fault, e.g. ``frames.3.t_s`` or ``camera.fx_px``.

The models are strict: a number must be a JSON number and a flag a JSON bool. pydantic's lax mode
took ``"fx_px": true`` as a focal length of 1 px (13.3 ± 2.0 deg/s, not a refusal) and ``"t_s":
"1.7"``, ``"fx_px": "2400"`` or ``"return_tracks": "yes"`` as if they were numbers and flags.
"""

from __future__ import annotations

import itertools
import json
import re
import statistics
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, Field, ValidationError

from ..errors import InputError
from ..imaging.camera import PinholeCamera
from ..imaging.camera_meta import STRICT_META, JsonInt
from ..imaging.camera_meta import CameraMeta as SharedCameraMeta
from ..io.manifest import manifest_object, read_manifest

INPUT_SCHEMA = "tumblescan.spin_from_images.input/1"
MIN_FRAMES = 6
MIN_SIDE_PX = 32
# What a strict type error expects, by pydantic's error type.
_EXPECTED = {
    "float_type": "a JSON number",
    "int_type": "a JSON integer",
    "int_from_float": "a JSON integer",
    "bool_type": "a JSON bool (true or false)",
    "string_type": "a JSON string",
    "list_type": "a JSON array",
    "model_type": "a JSON object",
    "dict_type": "a JSON object",
}


class FrameMeta(BaseModel):
    model_config = STRICT_META

    file: str = Field(min_length=1)
    t_s: float


class CameraMeta(SharedCameraMeta):
    width_px: JsonInt = Field(ge=MIN_SIDE_PX)
    height_px: JsonInt = Field(ge=MIN_SIDE_PX)
    pixel_origin: Literal["center_of_top_left_pixel"] = "center_of_top_left_pixel"


class PriorMeta(BaseModel):
    model_config = STRICT_META

    motion: Literal["single_axis_spin"] = "single_axis_spin"
    max_rate_deg_s: float | None = Field(None, gt=0)
    min_rate_deg_s: float | None = Field(None, ge=0)
    target_polarity: Literal["bright", "dark"] = "bright"


class MetaOptions(BaseModel):
    model_config = STRICT_META

    return_tracks: bool = False


class SpinInput(BaseModel):
    """meta.json: the frames (file relative to meta.json, mid-exposure time), the camera and the prior."""

    model_config = STRICT_META

    schema_: str = Field(alias="schema")
    frames: list[FrameMeta]
    time_reference: Literal["mid_exposure"] = "mid_exposure"
    exposure_s: float | None = Field(None, ge=0)
    epoch_utc: str | None = None
    camera: CameraMeta
    prior: PriorMeta = Field(default_factory=PriorMeta)
    options: MetaOptions = Field(default_factory=MetaOptions)

    @property
    def pinhole(self) -> PinholeCamera:
        return self.camera.pinhole()


def parse_meta(data: bytes | str, field: str = "meta") -> SpinInput:
    """Validate meta.json text; ``InputError`` naming the field otherwise."""
    raw = manifest_object(data, INPUT_SCHEMA, field=field)
    try:
        meta = SpinInput.model_validate(raw)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(x) for x in err["loc"]).replace("schema_", "schema")
        raise InputError(f"{loc}: {_message(err)}", field=loc) from None
    _check(meta)
    return meta


def _message(err: Any) -> str:
    """pydantic's message, or for a value of the wrong JSON type what was expected and what came."""
    expected = _EXPECTED.get(err["type"])
    if expected is None:
        return str(err["msg"])
    return f"{expected} is expected, not {_json_value(err['input'])}"


def _json_value(value: Any) -> str:
    """A JSON value in words: ``the bool true``, ``the string "2400"``, ``null``, ``an object``."""
    if isinstance(value, dict):
        return "an object"
    if isinstance(value, list):
        return "an array"
    if value is None:
        return "null"
    text = json.dumps(value)
    text = text if len(text) <= 40 else text[:37] + "..."
    kind = "bool" if isinstance(value, bool) else "string" if isinstance(value, str) else "number"
    return f"the {kind} {text}"


def read_meta(path: Path) -> SpinInput:
    """Read and validate meta.json from ``path``."""
    return parse_meta(read_manifest(path))


def _check(meta: SpinInput) -> None:
    if len(meta.frames) < MIN_FRAMES:
        raise InputError(f"frames: {len(meta.frames)} frames (at least {MIN_FRAMES} needed)", field="frames")
    for i in range(1, len(meta.frames)):
        if not meta.frames[i].t_s > meta.frames[i - 1].t_s:
            raise InputError(
                f"frames.{i}.t_s: {meta.frames[i].t_s} does not follow {meta.frames[i - 1].t_s} "
                "(times must strictly increase)",
                field=f"frames.{i}.t_s",
            )
    _check_exposure(meta)
    if meta.epoch_utc is not None:
        utc_epoch(meta.epoch_utc)
    names = [f.file for f in meta.frames]
    if len(set(names)) != len(names):
        raise InputError("frames: a file is named twice", field="frames")
    for i, name in enumerate(names):
        if Path(name).is_absolute() or ".." in Path(name).parts or "\\" in name:
            raise InputError(
                f"frames.{i}.file: {name!r} must be a relative path inside the input", field=f"frames.{i}.file"
            )
    meta.camera.check()
    p = meta.prior
    if p.min_rate_deg_s is not None and p.max_rate_deg_s is not None and p.min_rate_deg_s > p.max_rate_deg_s:
        raise InputError(
            f"prior.min_rate_deg_s: {p.min_rate_deg_s} is over max_rate_deg_s {p.max_rate_deg_s}",
            field="prior.min_rate_deg_s",
        )


def _check_exposure(meta: SpinInput) -> None:
    """One camera's exposures cannot overlap, but times rounded to the millisecond can make a
    whole-frame exposure look a little longer than the interval (0.0333 s at 30 fps against 0.033
    s): only an exposure over twice the median interval is refused, a unit mistake (ms for s) or
    a wrong field rather than data."""
    if meta.exposure_s is None:
        return
    gap = statistics.median(b.t_s - a.t_s for a, b in itertools.pairwise(meta.frames))
    if meta.exposure_s > 2 * gap:
        raise InputError(
            f"exposure_s: {meta.exposure_s:g} s is over twice the frames' median interval ({gap:g} s); "
            "one camera's exposures cannot overlap",
            field="exposure_s",
        )


def utc_epoch(text: str) -> datetime:
    """``epoch_utc`` as a UTC time: an ISO-8601 date and time with ``Z``, ``+00:00`` or no offset
    (the field says UTC). A date alone, another offset or free text (``"yesterday"``) is refused."""
    bad = InputError(
        f"epoch_utc: {text!r} is not an ISO-8601 UTC date and time (e.g. 2024-05-01T12:00:00Z)", field="epoch_utc"
    )
    if not re.search(r"\d[T ]\d", text):
        raise bad
    try:
        when = datetime.fromisoformat(text)
    except ValueError:
        raise bad from None
    if when.utcoffset() not in (None, timedelta(0)):
        raise InputError(f"epoch_utc: {text!r} is not in UTC (give it with Z or +00:00)", field="epoch_utc")
    return when
