"""The input contract ``tumblescan.panel_axis.input/1``: meta.json, validated once at the door.

Every refusal is an ``InputError`` (code ``invalid_input``) whose ``field`` names the field at
fault, e.g. ``camera.fx_px`` or ``pointing.R_cam_from_ref``. Numbers are strict: a JSON number,
never a bool or a string coerced to one (``"fx_px": true`` was a focal length of 1 px, and the job
succeeded with a confident, wrong tilt); integers (image sizes, ``wings``) are JSON integers.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, Field, ValidationError

from .._typing import FloatArray
from ..errors import InputError
from ..imaging.camera import PinholeCamera
from ..imaging.camera_meta import STRICT_META, JsonInt
from ..imaging.camera_meta import CameraMeta as SharedCameraMeta
from ..imaging.image_io import MIN_SIDE_PX
from ..io.manifest import manifest_object, read_manifest
from .frames import R_cam_from_enu

INPUT_SCHEMA = "tumblescan.panel_axis.input/1"


class CameraMeta(SharedCameraMeta):
    width_px: JsonInt = Field(ge=MIN_SIDE_PX)
    height_px: JsonInt = Field(ge=MIN_SIDE_PX)


class AnglePointing(BaseModel):
    model_config = STRICT_META

    frame: Literal["station_enu"] = "station_enu"
    azimuth_deg: float = Field(ge=-360, le=360)
    elevation_deg: float = Field(ge=-90, le=90)
    roll_deg: float = Field(0.0, ge=-360, le=360)


class MatrixPointing(BaseModel):
    model_config = STRICT_META

    frame: Literal["station_enu", "ecef"]
    R_cam_from_ref: list[list[float]]


class StationMeta(BaseModel):
    model_config = STRICT_META

    lat_deg: float = Field(ge=-90, le=90)
    lon_deg: float = Field(ge=-180, le=360)
    height_m: float = Field(0.0, ge=-1e4, le=1e6)  # below the deepest trench to above any airborne station


class PriorMeta(BaseModel):
    model_config = STRICT_META

    range_m: float | None = Field(None, gt=0, le=1e9)  # beyond GEO (3.6e7 m) and the Moon (3.8e8 m)
    panel_length_m: float | None = Field(None, gt=0, le=1e3)
    panel_width_m: float | None = Field(None, gt=0, le=1e3)
    wings: JsonInt = Field(2, ge=1, le=2)


class PanelAxisInput(BaseModel):
    """meta.json: the image's file name (relative to meta.json), the camera, and the optional
    pointing, station and panel prior."""

    model_config = STRICT_META

    schema_: str = Field(alias="schema")
    image: str = "image.png"
    camera: CameraMeta
    pointing: AnglePointing | MatrixPointing | None = None
    station: StationMeta | None = None
    prior: PriorMeta | None = None

    @property
    def pinhole(self) -> PinholeCamera:
        return self.camera.pinhole()

    @property
    def R_cam_from_ref(self) -> FloatArray | None:
        """The pointing as a rotation (rows: camera axes in the reference frame), or None."""
        p = self.pointing
        if p is None:
            return None
        if isinstance(p, AnglePointing):
            return R_cam_from_enu(p.azimuth_deg, p.elevation_deg, p.roll_deg)
        return np.asarray(p.R_cam_from_ref, dtype=float)

    @property
    def prior_complete(self) -> bool:
        """Whether the prior gives the panel's length and width (what IPPE needs)."""
        return self.prior is not None and self.prior.panel_length_m is not None and self.prior.panel_width_m is not None


def parse_meta(data: bytes | str, field: str = "meta") -> PanelAxisInput:
    """Validate meta.json text; ``InputError`` naming the field otherwise."""
    raw = manifest_object(data, INPUT_SCHEMA, field=field)
    if isinstance(raw.get("pointing"), dict):  # pick the pointing form by its keys, for clear messages
        raw["pointing"] = _pointing(raw["pointing"])
    try:
        meta = PanelAxisInput.model_validate(raw)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(x) for x in err["loc"] if not str(x).startswith(("AnglePointing", "MatrixPointing")))
        loc = loc.replace("schema_", "schema")
        raise InputError(f"{loc}: {_message(err)}", field=loc) from None
    _check(meta)
    return meta


def read_meta(path: Path) -> PanelAxisInput:
    """Read and validate meta.json from ``path``."""
    return parse_meta(read_manifest(path))


def _pointing(p: dict[str, Any]) -> AnglePointing | MatrixPointing:
    model: type[AnglePointing] | type[MatrixPointing] = MatrixPointing if "R_cam_from_ref" in p else AnglePointing
    try:
        return model.model_validate(p)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = "pointing." + ".".join(str(x) for x in err["loc"])
        raise InputError(f"{loc}: {_message(err)}", field=loc) from None


def _message(err: Any) -> str:
    """pydantic's message, saying what was given when a number was expected and a bool or a string
    came (strict mode's "Input should be a valid number" alone does not tell ``true`` from ``1.5``)."""
    value = err.get("input")
    if err["type"] == "float_type" and isinstance(value, bool | str):
        return f"a number is expected (a JSON number), not {json.dumps(value)}"
    return str(err["msg"])


def _check(meta: PanelAxisInput) -> None:
    meta.camera.check()
    if isinstance(meta.pointing, MatrixPointing):
        R = np.asarray(meta.pointing.R_cam_from_ref, dtype=float)
        if R.shape != (3, 3):
            raise InputError("pointing.R_cam_from_ref: a 3x3 matrix is expected", field="pointing.R_cam_from_ref")
        if np.abs(R @ R.T - np.eye(3)).max() > 1e-6 or not math.isclose(float(np.linalg.det(R)), 1.0, abs_tol=1e-6):
            raise InputError(
                "pointing.R_cam_from_ref: not a rotation (orthonormal to 1e-6 with determinant +1)",
                field="pointing.R_cam_from_ref",
            )


def check_image_size(meta: PanelAxisInput, gray: FloatArray, field: str = "image") -> None:
    """The image must be ``width_px`` x ``height_px``."""
    h, w = gray.shape
    c = meta.camera
    if (w, h) != (c.width_px, c.height_px):
        raise InputError(
            f"camera.width_px/height_px: the image is {w}x{h} px, meta.json says {c.width_px}x{c.height_px}",
            field="camera.width_px",
        )
