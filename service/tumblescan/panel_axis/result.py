"""The result contract ``tumblescan.panel_axis.result/1`` (see docs/panel_axis.md)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

RESULT_SCHEMA = "tumblescan.panel_axis.result/1"

Vec = list[float]
Mat = list[list[float]]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Axis(_Model):
    """The panel axis (a line: ``station_enu`` has North >= 0, ``ecef`` y >= 0, ``camera`` the same
    sign as the station vector, or x >= 0 without pointing). Frames absent from the input are null."""

    camera: Vec
    station_enu: Vec | None = None
    ecef: Vec | None = None
    pitch_deg: float | None = None
    yaw_deg: float | None = None
    pitch_ecef_deg: float | None = None
    yaw_ecef_deg: float | None = None
    sigma_deg: float | None = None
    cov_tangent_rad2: Mat | None = None
    tangent_basis_enu: Mat | None = None
    tangent_basis_camera: Mat | None = None
    sigma_pitch_deg: float | None = None
    sigma_yaw_deg: float | None = None


class Candidate(_Model):
    """One of the weak-perspective pair, with its pitch/yaw and their σ like ``Axis`` (the twin is
    as likely the panel's as the primary, so it gets the same numbers)."""

    kind: Literal["primary", "mirror"]
    camera: Vec
    station_enu: Vec | None = None
    ecef: Vec | None = None
    cost: float
    sigma_deg: float | None = None
    pitch_deg: float | None = None
    yaw_deg: float | None = None
    sigma_pitch_deg: float | None = None
    sigma_yaw_deg: float | None = None


class Direction(_Model):
    camera: Vec
    station_enu: Vec | None = None
    ecef: Vec | None = None


class Observability(_Model):
    regime: Literal["perspective", "weak_perspective"]
    perspective_snr: float | None = None
    tilt_deg: float | None = None
    sigma_tilt_deg: float | None = None


class Panel(_Model):
    """``short_axis`` (wing ends, sub-panel gaps) and ``normal``; ``frame`` says how the short axis
    was fitted: ``constrained`` ⟂ the reported axis (orthogonal to it by construction, so ``orthogonality_deg``
    is 0) or ``separate`` (its edges disagree with a right angle). ``table2_orthogonality_deg`` is
    the paper's Table 2 check between the two families' separate fits, with its σ."""

    short_axis: Direction | None = None
    short_axis_sigma_deg: float | None = None
    normal: Direction | None = None
    frame: Literal["constrained", "separate"] | None = None
    orthogonality_deg: float | None = None
    orthogonality_sigma_deg: float | None = None
    table2_orthogonality_deg: float | None = None
    table2_orthogonality_sigma_deg: float | None = None
    edge_rms_px: float | None = None
    edges_px: Mat = []
    short_edges_px: Mat = []
    wing_corners_px: Mat | None = None
    long_edges: int = 0
    short_edges: int = 0


class Segmentation(_Model):
    threshold: float
    target_px: int
    bbox_px: list[int] | None = None
    elongation: float | None = None
    tip_width_px: float | None = None


class PanelAxisResult(_Model):
    """The whole result (``result.json``)."""

    model_config = ConfigDict(extra="forbid", populate_by_name=True)

    schema_: str = Field(RESULT_SCHEMA, alias="schema")
    status: Literal["succeeded"] = "succeeded"
    method: Literal["ours", "paper"] = "ours"
    axis: Axis | None
    ambiguous: bool
    candidates: list[Candidate] = []
    image_angle_deg: float
    sigma_image_angle_deg: float | None = None
    axis_plane_normal: Direction
    observability: Observability
    panel: Panel
    segmentation: Segmentation
    warnings: list[str] = []
    timings_ms: dict[str, float] = {}

    def to_json(self) -> dict[str, object]:
        """The JSON document, ``schema`` first."""
        return self.model_dump(mode="json", by_alias=True)
