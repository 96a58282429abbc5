"""``tumblescan.bearings.result/1``: the result document and its model.

The estimator builds the document as plain dicts and lists (fast for thousands of targets);
the pydantic models below describe it (``GET /v1/kinds/bearings``) and validate it in tests.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

RESULT_SCHEMA = "tumblescan.bearings.result/1"
FLAGS = ("ambiguous", "low_parallax", "corrected_by_track")


class Geodetic(BaseModel):
    lat_deg: float
    lon_deg: float
    height_m: float


class Target(BaseModel):
    """One associated pair of detections and its position."""

    model_config = ConfigDict(extra="allow")
    id: str
    track: str | None = None
    position_m: list[float]
    cov_m2: list[list[float]]
    sigma_m: list[float]
    detections: dict[str, str]
    chi2: float
    range_m: list[float]
    parallax_deg: float
    flags: list[str]
    geodetic: Geodetic | None = None


class FrameResult(BaseModel):
    model_config = ConfigDict(extra="allow")
    index: int
    t: float
    targets: list[Target]
    unassociated: dict[str, list[str]]


class Summary(BaseModel):
    model_config = ConfigDict(extra="allow")
    targets: int
    ambiguous: int
    unassociated: dict[str, int]
    tracks: int = Field(default=0, description="tracks fitted, the length of tracks[]")
    short_tracks: int = Field(
        default=0, description="track ids too short to fit (fewer than 3 fixes): on targets, not in tracks[]"
    )
    method: str = "ml"


class TrackFit(BaseModel):
    """A track's motion fitted through its fixes (position, velocity, covariance at ``t_ref``)."""

    model_config = ConfigDict(extra="allow")
    id: str
    frames: list[int]
    t_ref: float
    model: str
    position_m: list[float]
    velocity_m_s: list[float]
    acceleration_m_s2: list[float] | None = None
    cov_m2: list[list[float]]
    velocity_cov_m2_s2: list[list[float]]
    chi2: float
    dof: int
    fixes_used: int


class ErrorInfo(BaseModel):
    code: str
    message: str
    field: str | None = None


class BearingsResult(BaseModel):
    """The whole document; ``status`` is ``succeeded`` (frames, summary) or ``failed`` (error)."""

    model_config = ConfigDict(extra="allow", populate_by_name=True)
    schema_: str = Field(default=RESULT_SCHEMA, alias="schema")
    status: Literal["succeeded", "failed"]
    kind: Literal["bearings"] = "bearings"
    frame: Literal["local_enu", "ecef"] | None = None
    frames: list[FrameResult] = []
    summary: Summary | None = None
    tracks: list[TrackFit] = []
    warnings: list[str] = []
    timings_ms: dict[str, float] = {}
    error: ErrorInfo | None = None


def failure_document(code: str, message: str, field: str | None = None) -> dict[str, Any]:
    """The failed result: ``{"schema", "status": "failed", "kind", "error": {code, message, field}}``."""
    return {
        "schema": RESULT_SCHEMA,
        "status": "failed",
        "kind": "bearings",
        "error": {"code": code, "message": message, "field": field},
    }
