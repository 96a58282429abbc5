"""``panel-axis``: the solar-panel axis result, mirroring the service's contract
(``tumblescan.panel_axis.result/1``)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

Vec = list[float]
Mat = list[list[float]]


class _Model(BaseModel):
    model_config = ConfigDict(extra="allow")


class Axis(_Model):
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
    kind: Literal["primary", "mirror"]
    camera: Vec
    station_enu: Vec | None = None
    ecef: Vec | None = None
    cost: float
    sigma_deg: float | None = None
    # The candidate's pitch and yaw in the station frame (older services: None).
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
    """``axis`` is null in weak perspective without a panel-size prior (then only
    ``image_angle_deg`` and ``axis_plane_normal`` are known); ``ambiguous`` means ``candidates``
    holds the axis and its mirror twin."""

    model_config = ConfigDict(extra="allow", populate_by_name=True)

    schema_: str = Field("tumblescan.panel_axis.result/1", alias="schema")
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
