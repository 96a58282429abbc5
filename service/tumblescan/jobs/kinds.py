"""Pluggable job kinds. A kind validates its input when the job is submitted and runs it in a
worker; the queue, the store and the routes know kinds only through this registry."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from pydantic import BaseModel


class JobCancelledError(Exception):
    """Raised at a progress check once the job's cancellation was requested."""


@dataclass
class JobContext:
    """What a running job sees: its options, stored inputs, a place for outputs and a
    progress reporter that is also the cancellation point."""

    job_id: str
    options: dict[str, Any]
    inputs: dict[str, Path]
    output_path: Callable[[str], Path]
    report: Callable[[str, float], None]

    def progress(self, stage: str, fraction: float) -> None:
        self.report(stage, fraction)


@dataclass(frozen=True)
class Limits:
    """Input sizes a deployment accepts."""

    max_observations: int
    max_cloud_points: int


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
    name: str
    options_model: type[BaseModel]

    def accept_json(self, payload: Any, save: Callable[[str, bytes], Path], limits: Limits) -> dict[str, str]:
        """Validate a JSON ``input``; store what the job needs; return input name -> file name."""
        ...

    def accept_files(self, files: dict[str, Path], limits: Limits, options: dict[str, Any]) -> dict[str, str]:
        """Validate uploaded files (already stored) with the job's validated options; return
        input name -> file name."""
        ...

    def run(self, ctx: JobContext) -> JobOutput: ...

    def report(self, job: FinishedJob) -> str:
        """The job's HTML report (built on first request, then kept with its artifacts)."""
        ...


REGISTRY: dict[str, JobKind] = {}


def register(kind: JobKind) -> JobKind:
    REGISTRY[kind.name] = kind
    return kind


def get_kind(name: str) -> JobKind:
    from . import linescan  # noqa: F401  (registers the built-in kinds)

    if name not in REGISTRY:
        raise KeyError(name)
    return REGISTRY[name]


def kind_names() -> list[str]:
    from . import linescan  # noqa: F401

    return sorted(REGISTRY)
