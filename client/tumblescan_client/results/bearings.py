"""The ``bearings`` result (``tumblescan.bearings.result/1``) as the client sees it.

Mirrors the service's model; unknown fields are kept (``extra="allow"``) so a newer service
does not break an older client.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class _Model(BaseModel):
    model_config = ConfigDict(extra="allow", populate_by_name=True)


class Geodetic(_Model):
    lat_deg: float
    lon_deg: float
    height_m: float


class BearingsTarget(_Model):
    """One associated pair of detections: where the target is and how well that is known."""

    id: str
    track: str | None = None
    position_m: list[float]
    cov_m2: list[list[float]]
    sigma_m: list[float]
    detections: dict[str, str]  # station id -> detection id: the association
    chi2: float
    range_m: list[float]
    parallax_deg: float
    flags: list[str]  # ambiguous, low_parallax, corrected_by_track
    geodetic: Geodetic | None = None


class BearingsFrame(_Model):
    index: int
    t: float
    targets: list[BearingsTarget]
    unassociated: dict[str, list[str]]  # station id -> detection ids in no target


class BearingsSummary(_Model):
    targets: int
    ambiguous: int
    unassociated: dict[str, int]
    tracks: int = 0  # fitted tracks, as many as ``tracks`` lists
    short_tracks: int = 0  # linked track ids with too few fixes to fit (older services: 0)
    method: str = "ml"


class BearingsTrack(_Model):
    """A track's motion fitted through its fixes (position, velocity, covariance at ``t_ref``)."""

    id: str
    frames: list[int]
    t_ref: float
    model: str  # constant_velocity or constant_acceleration
    position_m: list[float]
    velocity_m_s: list[float]
    acceleration_m_s2: list[float] | None = None
    cov_m2: list[list[float]]
    velocity_cov_m2_s2: list[list[float]]
    chi2: float
    dof: int
    fixes_used: int


class BearingsError(_Model):
    code: str
    message: str
    field: str | None = None


class BearingsResult(_Model):
    """The whole result; ``status`` is ``succeeded`` (frames, summary) or ``failed`` (error)."""

    schema_: str = Field(default="tumblescan.bearings.result/1", alias="schema")
    status: Literal["succeeded", "failed"]
    kind: Literal["bearings"] = "bearings"
    frame: Literal["local_enu", "ecef"] | None = None
    frames: list[BearingsFrame] = []
    summary: BearingsSummary | None = None
    tracks: list[BearingsTrack] = []
    warnings: list[str] = []
    timings_ms: dict[str, float] = {}
    error: BearingsError | None = None

    def targets_by_track(self) -> dict[str, list[BearingsTarget]]:
        """Every target grouped by track id, in frame order (targets without a track left out)."""
        out: dict[str, list[BearingsTarget]] = {}
        for fr in self.frames:
            for t in fr.targets:
                if t.track is not None:
                    out.setdefault(t.track, []).append(t)
        return out
