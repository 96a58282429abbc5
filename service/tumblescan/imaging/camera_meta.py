"""The ``camera`` block of an optical kind's meta.json, validated at the door (strictly, as the
kinds' other meta.json models: ``STRICT_META``), and the :class:`PinholeCamera` it describes.
Each kind subclasses it to set its own smallest image side (``width_px`` and ``height_px`` are
redeclared there with the bound)."""

from __future__ import annotations

import json
from typing import Annotated, Any, Literal

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, Strict
from pydantic_core import PydanticCustomError

from ..errors import InputError
from .camera import PinholeCamera
from .image_io import MAX_PIXELS


def _json_integer(value: Any) -> Any:
    """An integer field of a kind's strict meta.json (``JsonInt``) takes a whole JSON number (640,
    or 640.0 as some writers put it), never a bool or a string: strict mode would refuse 640.0
    too, lax mode would take true as 1."""
    if isinstance(value, bool | str):
        raise PydanticCustomError(
            "int_type", "an integer is expected (a JSON number), not {given}", {"given": json.dumps(value)}
        )
    return value


JsonInt = Annotated[int, Strict(False), BeforeValidator(_json_integer)]


# A kind's meta.json models: no unknown field, no NaN, and no bool or string taken as a number
# (lax mode took "fx_px": true as a focal length of 1 px and gave a confident wrong answer).
STRICT_META = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True)


class CameraMeta(BaseModel):
    model_config = STRICT_META

    model: Literal["pinhole"] = "pinhole"
    width_px: JsonInt = Field(ge=1)
    height_px: JsonInt = Field(ge=1)
    # Upper bounds only refuse the absurd (1e308 was accepted and the job failed far from the
    # cause): a 10 m focal length on 0.1 µm pixels is 1e8 px; OpenCV's coefficients stay far under 1e3.
    fx_px: float = Field(gt=0, le=1e8)
    fy_px: float = Field(gt=0, le=1e8)
    cx_px: float
    cy_px: float
    skew: float = Field(0.0, ge=-1e8, le=1e8)
    distortion: list[Annotated[float, Field(ge=-1e3, le=1e3)]] | None = None

    def check(self) -> None:
        """What the fields' own bounds cannot say, refused naming the field under ``camera``: an
        image over ``MAX_PIXELS``, a principal point outside the image (1e6 px gave a spin rate
        86 % off with a sigma of 96 deg/s instead of a refusal), distortion not of 5 coefficients."""
        if self.width_px * self.height_px > MAX_PIXELS:
            limit = f"{MAX_PIXELS // 1_000_000} Mpx"
            raise InputError(f"camera: {self.width_px}x{self.height_px} px is over the {limit} limit",
                             field="camera.width_px")  # fmt: skip
        for name, value, side in (("cx_px", self.cx_px, self.width_px), ("cy_px", self.cy_px, self.height_px)):
            if not -0.5 <= value <= side - 0.5:
                raise InputError(f"camera.{name}: {value} is outside the image [-0.5, {side - 0.5}]",
                                 field=f"camera.{name}")  # fmt: skip
        if self.distortion is not None and len(self.distortion) != 5:
            raise InputError(
                f"camera.distortion: {len(self.distortion)} coefficients (OpenCV [k1, k2, p1, p2, k3] expected)",
                field="camera.distortion",
            )

    def pinhole(self) -> PinholeCamera:
        dist = tuple(self.distortion) if self.distortion is not None else None
        return PinholeCamera(
            self.width_px,
            self.height_px,
            self.fx_px,
            self.fy_px,
            self.cx_px,
            self.cy_px,
            self.skew,
            dist,  # type: ignore[arg-type]
        )
