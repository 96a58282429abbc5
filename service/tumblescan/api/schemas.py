"""Request and response bodies, split by role."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from ..jobs.kind import InputForm, JobKind
from ..jobs.registry import kinds
from ..jobs.tables import Job

Status = Literal["queued", "running", "succeeded", "failed", "cancelled"]
DEFAULT_KIND = "linescan-motion"  # what a request without a kind means (the first kind served)
REPORT_TEXT = "the job's self-contained HTML report"


class JobCreate(BaseModel):
    """``POST /v1/jobs``: a job from JSON input."""

    model_config = ConfigDict(extra="forbid")

    kind: str = Field(DEFAULT_KIND, examples=[DEFAULT_KIND], description="GET /v1/kinds lists them")
    input: dict[str, Any] = Field(description='the kind\'s JSON input (linescan-motion: {"tracks": <tracks JSON>})')
    options: dict[str, Any] = Field(default_factory=dict, description="the kind's options; unknown names are a 422")


class JobError(BaseModel):
    code: str
    message: str


class ArtifactPublic(BaseModel):
    name: str
    media_type: str
    description: str
    url: str
    filename: str = Field(description="a file name to save it as, with its extension (cloud.ply, report.html)")


class JobPublic(BaseModel):
    id: str
    kind: str
    status: Status
    cancel_requested: bool = Field(
        description="a cancellation was asked for (DELETE); a running job stays 'running' until it stops, "
        "within seconds, then is 'cancelled'"
    )
    progress: float = Field(ge=0, le=1)
    stage: str
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    error: JobError | None
    result: dict[str, Any] | None = Field(description="the kind's result (GET /v1/kinds/{kind} has its schema)")
    artifacts: dict[str, str] = Field(
        description="artifact name -> URL (the kind's files, e.g. 'cloud', and 'report') once the job has succeeded"
    )

    @classmethod
    def from_job(cls, job: Job, base_url: str) -> JobPublic:
        succeeded = job.status == "succeeded" and not job.artifacts_deleted
        # The line-scan cloud keeps its short URL (clients before the artifacts routes use it).
        links = {
            name: f"{base_url}/v1/jobs/{job.id}/" + ("cloud" if name == "cloud" else f"artifacts/{name}")
            for name in (job.artifacts if succeeded else {})
        }
        if succeeded:
            links["report"] = f"{base_url}/v1/jobs/{job.id}/report"

        return cls(
            id=job.id,
            kind=job.kind,
            status=job.status,
            cancel_requested=job.cancel_requested,
            progress=job.progress,
            stage=job.stage,
            created_at=datetime.fromtimestamp(job.created_at, UTC),
            started_at=_ts(job.started_at),
            finished_at=_ts(job.finished_at),
            error=JobError(code=job.error_code, message=job.error_message or "") if job.error_code else None,
            result=job.result,
            artifacts=links,
        )


class JobList(BaseModel):
    items: list[JobPublic]
    next_cursor: str | None = Field(description="pass as ?cursor= for the next page; null on the last page")


class ErrorBody(BaseModel):
    detail: Any


def _ts(t: float | None) -> datetime | None:
    return None if t is None else datetime.fromtimestamp(t, UTC)


class InputPartPublic(BaseModel):
    name: str
    description: str
    formats: list[str]
    required: bool
    many: bool = Field(description="several files may come under this field")


class InputFormPublic(BaseModel):
    name: str
    description: str
    parts: list[InputPartPublic] = Field(description="upload fields of POST /v1/jobs/upload")
    json_input: bool = Field(description="the form can also come as the JSON input of POST /v1/jobs")
    json_schema: dict[str, Any] | None = Field(description="JSON schema of that input")
    options_schema: dict[str, Any] = Field(description="JSON schema of the form's options (unknown names are a 422)")

    @classmethod
    def from_form(cls, form: InputForm) -> InputFormPublic:
        parts = [
            InputPartPublic(name=p.name, description=p.description, formats=list(p.formats), required=p.required,
                            many=p.many)
            for p in form.parts
        ]  # fmt: skip
        return cls(
            name=form.name,
            description=form.description,
            parts=parts,
            json_input=form.json_input,
            json_schema=form.json_schema,
            options_schema=form.options.model_json_schema(),
        )


class ArtifactSpecPublic(BaseModel):
    name: str
    media_type: str
    description: str


class KindSummary(BaseModel):
    name: str
    title: str
    url: str


class KindPublic(BaseModel):
    name: str
    title: str
    forms: list[InputFormPublic]
    result_schema: dict[str, Any]
    artifacts: list[ArtifactSpecPublic] = Field(description="files a job may write, beside its 'report'")
    limits: dict[str, Any] = Field(description="this deployment's limits for the kind")

    @classmethod
    def from_kind(cls, kind: JobKind, limits: BaseModel) -> KindPublic:
        return cls(
            name=kind.name,
            title=kind.title,
            forms=[InputFormPublic.from_form(f) for f in kind.forms],
            result_schema=kind.result_model.model_json_schema(),
            artifacts=[
                ArtifactSpecPublic(name=a.name, media_type=a.media_type, description=a.description)
                for a in kind.artifacts
            ],
            limits=limits.model_dump(mode="json"),
        )


def upload_schema() -> dict[str, Any]:
    """The multipart body of POST /v1/jobs/upload: ``kind``, ``options`` and every kind's parts."""
    properties: dict[str, Any] = {
        "kind": {"type": "string", "enum": sorted(kinds()), "default": DEFAULT_KIND},
        "options": {"type": "string", "description": "the options of the input's form, as a JSON object"},
    }
    for kind in kinds().values():
        for form in kind.forms:
            for part in form.parts:
                binary = {"type": "string", "format": "binary"}
                schema = {"type": "array", "items": binary} if part.many else binary
                properties.setdefault(part.name, schema | {"description": f"{kind.name}: {part.description}"})
    return {"type": "object", "properties": properties}
