"""Request and response bodies, split by role."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from ..jobs.store import Job

Status = Literal["queued", "running", "succeeded", "failed", "cancelled"]


class JobCreate(BaseModel):
    """``POST /v1/jobs``: a job from JSON input."""

    model_config = ConfigDict(extra="forbid")

    kind: str = Field("linescan-motion", examples=["linescan-motion"])
    input: dict[str, Any] = Field(description='for linescan-motion: {"tracks": <tracks JSON>}')
    options: dict[str, Any] = Field(default_factory=dict, description="the kind's options; unknown names are a 422")


class JobError(BaseModel):
    code: str
    message: str


class JobArtifacts(BaseModel):
    cloud: str | None = Field(None, description="URL of the rectified cloud (binary PLY)")
    report: str | None = Field(None, description="URL of the HTML report")


class JobPublic(BaseModel):
    id: str
    kind: str
    status: Status
    progress: float = Field(ge=0, le=1)
    stage: str
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    error: JobError | None
    result: dict[str, Any] | None = Field(description="the kind's result (linescan-motion: the motion result)")
    artifacts: JobArtifacts

    @classmethod
    def from_job(cls, job: Job, base_url: str) -> JobPublic:
        succeeded = job.status == "succeeded" and not job.artifacts_deleted
        report = f"{base_url}/v1/jobs/{job.id}/report" if succeeded else None

        def link(name: str) -> str | None:
            return (
                f"{base_url}/v1/jobs/{job.id}/{name}" if name in job.artifacts and not job.artifacts_deleted else None
            )

        return cls(
            id=job.id,
            kind=job.kind,
            status=job.status,
            progress=job.progress,
            stage=job.stage,
            created_at=datetime.fromtimestamp(job.created_at, UTC),
            started_at=_ts(job.started_at),
            finished_at=_ts(job.finished_at),
            error=JobError(code=job.error_code, message=job.error_message or "") if job.error_code else None,
            result=job.result,
            artifacts=JobArtifacts(cloud=link("cloud"), report=report),
        )


class JobList(BaseModel):
    items: list[JobPublic]
    next_cursor: str | None = Field(description="pass as ?cursor= for the next page; null on the last page")


class ErrorBody(BaseModel):
    detail: Any


def _ts(t: float | None) -> datetime | None:
    return None if t is None else datetime.fromtimestamp(t, UTC)
