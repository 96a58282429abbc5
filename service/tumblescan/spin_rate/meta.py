"""The input contract ``tumblescan.spin_from_images.input/1``: meta.json, validated once at the door.

Every refusal is an ``InputError`` (code ``invalid_input``) whose ``field`` names the field at
fault, e.g. ``frames.3.t_s`` or ``camera.fx_px``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from ..errors import InputError
from ..imaging.camera import PinholeCamera
from ..imaging.camera_meta import CameraMeta as SharedCameraMeta
from ..io.manifest import manifest_object, read_manifest

INPUT_SCHEMA = "tumblescan.spin_from_images.input/1"
MIN_FRAMES = 6
MIN_SIDE_PX = 32
MAX_PIXELS = 64_000_000
_STRICT = ConfigDict(extra="forbid", allow_inf_nan=False)


class FrameMeta(BaseModel):
    model_config = _STRICT

    file: str = Field(min_length=1)
    t_s: float


class CameraMeta(SharedCameraMeta):
    width_px: int = Field(ge=MIN_SIDE_PX)
    height_px: int = Field(ge=MIN_SIDE_PX)
    pixel_origin: Literal["center_of_top_left_pixel"] = "center_of_top_left_pixel"


class PriorMeta(BaseModel):
    model_config = _STRICT

    motion: Literal["single_axis_spin"] = "single_axis_spin"
    max_rate_deg_s: float | None = Field(None, gt=0)
    min_rate_deg_s: float | None = Field(None, ge=0)
    target_polarity: Literal["bright", "dark"] = "bright"


class MetaOptions(BaseModel):
    model_config = _STRICT

    return_tracks: bool = False


class SpinInput(BaseModel):
    """meta.json: the frames (file relative to meta.json, mid-exposure time), the camera and the prior."""

    model_config = _STRICT

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
        raise InputError(f"{loc}: {err['msg']}", field=loc) from None
    _check(meta)
    return meta


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
    names = [f.file for f in meta.frames]
    if len(set(names)) != len(names):
        raise InputError("frames: a file is named twice", field="frames")
    for i, name in enumerate(names):
        if Path(name).is_absolute() or ".." in Path(name).parts or "\\" in name:
            raise InputError(
                f"frames.{i}.file: {name!r} must be a relative path inside the input", field=f"frames.{i}.file"
            )
    c = meta.camera
    if c.width_px * c.height_px > MAX_PIXELS:
        raise InputError(f"camera: {c.width_px}x{c.height_px} px is over the 64 Mpx limit", field="camera.width_px")
    if c.distortion is not None and len(c.distortion) != 5:
        raise InputError(
            f"camera.distortion: {len(c.distortion)} coefficients (OpenCV [k1, k2, p1, p2, k3] expected)",
            field="camera.distortion",
        )
    p = meta.prior
    if p.min_rate_deg_s is not None and p.max_rate_deg_s is not None and p.min_rate_deg_s > p.max_rate_deg_s:
        raise InputError(
            f"prior.min_rate_deg_s: {p.min_rate_deg_s} is over max_rate_deg_s {p.max_rate_deg_s}",
            field="prior.min_rate_deg_s",
        )
