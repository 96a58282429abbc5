"""What a job kind declares, and what the job layer hands it.

A kind is one estimator served as jobs. It declares its name and title, the forms its input
can take (upload parts or a JSON ``input``, each form with its own options model), its
result model, the artifacts it writes and its limits; it accepts a submission (validating
everything before the job is queued) and runs a job, reporting progress. The queue, the
store, the routes, the client and the CLI know kinds only through this protocol and the
registry (``registry.py``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from pydantic import BaseModel


class JobCancelledError(Exception):
    """Raised at a progress check once the job's cancellation was requested."""


@dataclass(frozen=True)
class InputPart:
    """One upload field (multipart part) of a form."""

    name: str
    description: str
    formats: tuple[str, ...]  # accepted formats, e.g. ("json", "csv"); sniffed, never trusted from names
    required: bool = True
    many: bool = False  # several files may come under this one field (an image sequence)


@dataclass(frozen=True)
class InputForm:
    """One way of giving a kind its input, with the options that apply to it.

    ``parts`` are the upload fields (``POST /v1/jobs/upload``); ``json_input`` says whether the
    form can also come as the JSON ``input`` of ``POST /v1/jobs``, described by ``json_schema``.
    An option that is not in ``options`` is refused (422 naming it), never ignored.
    """

    name: str
    description: str
    options: type[BaseModel]
    parts: tuple[InputPart, ...] = ()
    json_input: bool = False
    json_schema: dict[str, Any] | None = None


@dataclass(frozen=True)
class ArtifactSpec:
    """A file a job of this kind may write (``GET /v1/jobs/{id}/artifacts/{name}``)."""

    name: str
    media_type: str
    description: str


@dataclass
class Submission:
    """What the service hands a kind to accept: the stored uploads (or the JSON input), the
    options validated against the chosen form, the kind's limits, and the job's directory,
    where the kind may write derived inputs (an unpacked zip, a normalised JSON)."""

    form: InputForm
    options: BaseModel
    limits: BaseModel
    job_dir: Path
    files: dict[str, list[Path]] = field(default_factory=dict)
    payload: Any = None

    def save(self, name: str, data: bytes) -> Path:
        """Write ``data`` as ``name`` in the job's directory (atomically) and return its path."""
        target = self.job_dir / name
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp = target.with_name(f".{target.name}.tmp")
        tmp.write_bytes(data)
        tmp.replace(target)
        return target


@dataclass
class JobContext:
    """What a running job sees: its options, stored inputs (name -> path), a place for outputs
    and a progress reporter that is also the cancellation point."""

    job_id: str
    options: dict[str, Any]
    inputs: dict[str, Path]
    output_path: Callable[[str], Path]
    report: Callable[[str, float], None]

    def progress(self, stage: str, fraction: float) -> None:
        self.report(stage, fraction)


@dataclass(frozen=True)
class FinishedJob:
    """A succeeded job's result and files, for building its report."""

    id: str
    result: dict[str, Any]
    options: dict[str, Any]
    inputs: dict[str, Path]
    artifacts: dict[str, Path]


@dataclass
class JobOutput:
    result: dict[str, Any]
    artifacts: dict[str, str] = field(default_factory=dict)  # artifact name -> file name in the job dir


class JobKind(Protocol):
    """A job kind. ``forms``, ``result_model``, ``artifacts`` and ``limits_model`` are what
    ``GET /v1/kinds/{name}`` publishes."""

    name: str
    title: str
    forms: tuple[InputForm, ...]
    result_model: type[BaseModel]
    artifacts: tuple[ArtifactSpec, ...]
    limits_model: type[BaseModel]

    def form_of(self, files: Mapping[str, list[Path]], payload: Any) -> InputForm:
        """The form a submission takes (from its parts, or by sniffing the files' first bytes);
        an ``InputError`` naming the field when it fits none."""
        ...

    def accept(self, sub: Submission) -> dict[str, str]:
        """Validate the whole input now (so a bad one is a 422, not a failed job); return
        input name -> path relative to the job's directory, for :meth:`run`."""
        ...

    def run(self, ctx: JobContext) -> JobOutput:
        """Run the job, calling ``ctx.progress(stage, fraction)`` between steps. Bad input the
        kind only finds now is an ``InputError`` (its ``code`` becomes the job's error code)."""
        ...

    def report(self, job: FinishedJob) -> str:
        """The job's self-contained HTML report (built on first request, then kept)."""
        ...


def form_named(kind: JobKind, name: str) -> InputForm:
    """The kind's form called ``name`` (a bug if there is none)."""
    for form in kind.forms:
        if form.name == name:
            return form
    raise KeyError(f"{kind.name} has no input form {name!r}")
