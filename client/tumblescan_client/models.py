"""Typed responses: jobs, pages of jobs, kinds. Each kind's result model is in ``results/``."""

from __future__ import annotations

from datetime import datetime
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict

from .results.linescan import MotionResult as MotionResult  # importable from here, as before results/

Status = Literal["queued", "running", "succeeded", "failed", "cancelled"]
FINAL = ("succeeded", "failed", "cancelled")


class _Model(BaseModel):
    model_config = ConfigDict(extra="allow")


class JobError(_Model):
    code: str
    message: str


class JobArtifacts(_Model):
    """Artifact name -> URL once the job has succeeded: the kind's files (``cloud`` for
    linescan-motion) and ``report``. Any name is also ``artifacts[name]``."""

    cloud: str | None = None
    report: str | None = None

    def __getitem__(self, name: str) -> str:
        value = self.urls().get(name)
        if value is None:
            raise KeyError(name)
        return value

    def urls(self) -> dict[str, str]:
        return {k: v for k, v in self.model_dump().items() if isinstance(v, str)}

    # Read like the dict of URLs it stands for (``keys``, ``items``, ``get``, ``in``); iterating
    # stays pydantic's own, which ``dict(model)`` relies on.
    def keys(self) -> list[str]:
        return list(self.urls())

    def items(self) -> list[tuple[str, str]]:
        return list(self.urls().items())

    def get(self, name: str, default: str | None = None) -> str | None:
        return self.urls().get(name, default)

    def __contains__(self, name: object) -> bool:
        return name in self.urls()

    def __len__(self) -> int:
        return len(self.urls())


class Job(_Model):
    id: str
    kind: str
    status: Status
    cancel_requested: bool = False  # a running job asked to stop (older services: False)
    progress: float
    stage: str
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    error: JobError | None
    result: dict[str, Any] | None
    artifacts: JobArtifacts

    @property
    def done(self) -> bool:
        return self.status in FINAL


class JobPage(_Model):
    items: list[Job]
    next_cursor: str | None


class InputPart(_Model):
    name: str
    description: str
    formats: list[str]
    required: bool
    many: bool


class InputForm(_Model):
    name: str
    description: str
    parts: list[InputPart]
    json_input: bool
    json_schema: dict[str, Any] | None
    options_schema: dict[str, Any]


class ArtifactSpec(_Model):
    name: str
    media_type: str
    description: str


class KindSummary(_Model):
    name: str
    title: str
    url: str


class Kind(_Model):
    """A job kind as the service describes it (``GET /v1/kinds/{name}``)."""

    name: str
    title: str
    forms: list[InputForm]
    result_schema: dict[str, Any]
    artifacts: list[ArtifactSpec]
    limits: dict[str, Any]

    def upload_parts(self) -> list[str]:
        """Every upload field of every form, in order, without repeats."""
        return list(dict.fromkeys(p.name for f in self.forms for p in f.parts))


class Artifact(_Model):
    name: str
    media_type: str
    description: str
    url: str
    filename: str | None = None  # a name to save it as, with its extension (older services: None)
