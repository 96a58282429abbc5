"""The job service: what the HTTP API and the CLI do with jobs, over store, artifacts and queue."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any, BinaryIO

from pydantic import BaseModel, ValidationError

from ..errors import InputError, MalformedInputError
from .artifacts import safe_name
from .kind import FinishedJob, InputForm, JobKind, Submission
from .registry import get_kind
from .runtime import Runtime
from .tables import FINAL, Job, new_id

log = logging.getLogger("tumblescan.service")
REPORT_FILE = "report.html"


class QueueUnavailableError(Exception):
    """The queue could not take the job; nothing was kept. Retry later."""


class ArtifactMissingError(Exception):
    """A succeeded job's file is no longer in the artifact store (removed by hand, or lost):
    gone for good, and nothing is being stored (the API answers 410, not 507)."""


class OptionsError(Exception):
    """Options failed validation; ``errors`` are pydantic's, each naming its option."""

    def __init__(self, errors: list[dict[str, Any]]) -> None:
        super().__init__("invalid options")
        self.errors = errors


Upload = tuple[str | None, BinaryIO]  # the uploader's file name (never trusted) and the stream


class JobService:
    def __init__(self, rt: Runtime, enqueue: Callable[[str], Any], pending: Callable[[], int]) -> None:
        self.rt = rt
        self.store = rt.store
        self.artifacts = rt.artifacts
        self._enqueue = enqueue
        self._pending = pending

    # Submission: the kind picks the form, the form's model validates the options, the kind
    # validates the whole input; only then is the job stored and queued.

    def submit_json(self, kind_name: str, payload: Any, options: dict[str, Any], owner: str | None) -> Job:
        kind = get_kind(kind_name)
        if not any(f.json_input for f in kind.forms):
            parts = ", ".join(dict.fromkeys(p.name for f in kind.forms for p in f.parts))
            raise InputError(
                f"{kind_name} takes its input as an upload (POST /v1/jobs/upload; parts: {parts}), not as JSON",
                field="input",
            )
        form = kind.form_of({}, payload)
        opts = self._options(kind, form, options)
        job_id = new_id()
        try:
            sub = Submission(form, opts, self.limits(kind), self.artifacts.job_dir(job_id), payload=payload)
            inputs = _accept(kind, sub, "input")
        except BaseException:
            self.artifacts.delete(job_id)
            raise
        return self._create_and_enqueue(job_id, kind_name, _dump(opts), inputs, owner)

    def submit_upload(
        self, kind_name: str, files: dict[str, list[Upload]], options: dict[str, Any], owner: str | None
    ) -> Job:
        kind = get_kind(kind_name)
        _check_fields(kind, files)
        _check_names(files)
        job_id = new_id()
        try:
            stored = {
                field: [
                    self.artifacts.save_upload(job_id, field, i, name, src, max_bytes=self.rt.settings.max_upload_bytes)
                    for i, (name, src) in enumerate(items)
                ]
                for field, items in files.items()
            }
            form = kind.form_of(stored, None)
            _check_parts(form, stored)
            opts = self._options(kind, form, options)
            sub = Submission(form, opts, self.limits(kind), self.artifacts.job_dir(job_id), files=stored)
            inputs = _accept(kind, sub, form.parts[0].name if len(form.parts) == 1 else "input")
        except BaseException:
            self.artifacts.delete(job_id)
            raise
        return self._create_and_enqueue(job_id, kind_name, _dump(opts), inputs, owner)

    def limits(self, kind: JobKind) -> BaseModel:
        """The kind's limits: its defaults, a setting of the same name (``TUMBLESCAN_MAX_...``),
        then ``TUMBLESCAN_LIMITS`` (``{"<kind>": {"<limit>": value}}``)."""
        s = self.rt.settings
        values = {name: getattr(s, name) for name in kind.limits_model.model_fields if hasattr(s, name)}
        return kind.limits_model.model_validate(values | s.limits.get(kind.name, {}))

    def _options(self, kind: JobKind, form: InputForm, options: dict[str, Any]) -> BaseModel:
        try:
            return form.options.model_validate(options)
        except ValidationError as exc:
            errors = [dict(e) for e in exc.errors(include_url=False, include_input=False)]
            raise OptionsError([_explain(e, kind, form) for e in errors]) from None

    def _create_and_enqueue(
        self, job_id: str, kind: str, options: dict[str, Any], inputs: dict[str, str], owner: str | None
    ) -> Job:
        job = self.store.create(job_id=job_id, kind=kind, options=options, input=inputs, owner=owner)
        try:
            self._enqueue(job_id)
        except Exception as exc:
            log.warning("queue unavailable: %s", exc)
            self.store.delete(job_id)
            self.artifacts.delete(job_id)
            raise QueueUnavailableError(str(exc)) from exc
        return job

    # Reads and cancellation.

    def get(self, job_id: str, owner: str | None) -> Job | None:
        return self.store.get(job_id, owner=owner)

    def list(
        self, *, status: str | None, owner: str | None, limit: int, cursor: str | None
    ) -> tuple[list[Job], str | None]:
        return self.store.list_jobs(status=status, owner=owner, limit=limit, cursor=cursor)

    def cancel(self, job_id: str, owner: str | None) -> Job | None:
        job = self.store.get(job_id, owner=owner)
        if job is None or job.status in FINAL:
            return job
        job = self.store.request_cancel(job_id)
        if job is not None and job.status == "cancelled":
            self._delete_artifacts(job)
        return job

    def report_path(self, job: Job) -> Path:
        """The succeeded job's report, built and stored on first request; ``ArtifactMissingError``
        naming the file it would be built from when that has gone from the store."""
        path = self.artifacts.path(job.id, REPORT_FILE)
        if path.exists():
            return path
        for what, files in (("input", job.input), ("artifact", job.artifacts)):
            for name, stored in files.items():
                if not self.artifacts.path(job.id, stored).exists():
                    raise ArtifactMissingError(
                        f"job {job.id}'s report cannot be built: its {what} {name!r} ({Path(stored).name}) "
                        "is no longer in the artifact store"
                    )
        finished = FinishedJob(
            id=job.id,
            result=job.result or {},
            options=job.options,
            inputs={k: self.artifacts.path(job.id, v) for k, v in job.input.items()},
            artifacts={k: self.artifacts.path(job.id, v) for k, v in job.artifacts.items()},
        )
        try:
            self.artifacts.save_bytes(job.id, REPORT_FILE, get_kind(job.kind).report(finished).encode("utf-8"))
        except FileNotFoundError as exc:  # gone while the report was being built
            gone = Path(exc.filename).name if exc.filename else "a file it reads"
            raise ArtifactMissingError(
                f"job {job.id}'s report cannot be built: {gone} is no longer in the artifact store"
            ) from None
        return path

    def queue_depth(self) -> int:
        return int(self._pending())

    # Housekeeping (the reaper).

    def reap_once(self) -> None:
        s = self.rt.settings
        # Running jobs whose worker stopped beating: run again, or fail as worker_lost.
        for job in self.store.stale_running(s.lease_s):
            status = self.store.reap(job, max_attempts=s.max_attempts, lease_s=s.lease_s)
            if status:
                log.warning("job %s lost its worker: now %s", job.id, status)
            if status == "queued":
                self._enqueue(job.id)
        # Queued jobs with nothing pending in the queue lost their task (a queue restart):
        # enqueue them again; a task for a job that is no longer queued does nothing.
        if self._pending() == 0:
            for job_id in self.store.queued_older_than(s.reaper_interval_s * 2):
                self._enqueue(job_id)
        for job in self.store.finished_with_artifacts():
            if job.status == "cancelled":
                self._delete_artifacts(job)

    def _delete_artifacts(self, job: Job) -> None:
        self.artifacts.delete(job.id)
        self.store.mark_artifacts_deleted(job.id)


class Reaper(threading.Thread):
    """Runs :meth:`JobService.reap_once` every ``interval`` seconds until stopped."""

    def __init__(self, service: JobService, interval_s: float) -> None:
        super().__init__(daemon=True, name="reaper")
        self.service, self.interval_s = service, interval_s
        self.stopped = threading.Event()

    def run(self) -> None:
        while not self.stopped.wait(self.interval_s):
            try:
                self.service.reap_once()
            except Exception:
                log.exception("reaper pass failed; retrying in %.0f s", self.interval_s)


def _dump(options: BaseModel) -> dict[str, Any]:
    return options.model_dump(mode="json", exclude_unset=True)


def _accept(kind: JobKind, sub: Submission, field: str) -> dict[str, str]:
    """``kind.accept``, where whatever escapes a kind's reader is still the submitter's 422:
    accept only reads and checks the input, so an exception it did not mean to raise (JSON
    nested past Python's recursion limit, an integer too large for an array) is input it
    could not read. It is logged with its traceback, as the reader's bug it also is. An
    ``OSError`` stays what it is: the artifact store failing (507)."""
    try:
        return kind.accept(sub)
    except (InputError, OSError):
        raise
    except RecursionError:
        raise MalformedInputError(f"{field}: the JSON nests too deeply to read", field=field) from None
    except Exception as exc:
        log.exception("%s: accept raised %s on a submission", kind.name, type(exc).__name__)
        raise MalformedInputError(
            f"{field}: the input could not be read ({type(exc).__name__}: {exc})", field=field
        ) from None


def _check_fields(kind: JobKind, files: dict[str, list[Upload]]) -> None:
    """Every upload field is one some form of the kind declares."""
    known = {part.name for form in kind.forms for part in form.parts}
    unknown = sorted(set(files) - known)
    if unknown:
        raise MalformedInputError(
            f"unknown upload field(s) for {kind.name}: {', '.join(unknown)} (it takes {', '.join(sorted(known))})",
            field=unknown[0],
        )


def _check_parts(form: InputForm, files: dict[str, list[Path]]) -> None:
    """Required parts present; one file where the part takes one; no part of another form."""
    declared = {part.name: part for part in form.parts}
    for name in files:
        if name not in declared:
            raise MalformedInputError(f"'{name}' does not go with {form.name} input", field=name)
    for part in form.parts:
        if part.required and not files.get(part.name):
            raise MalformedInputError(f"{form.name} input needs '{part.name}' ({part.description})", field=part.name)
        if not part.many and len(files.get(part.name, [])) > 1:
            raise MalformedInputError(f"'{part.name}' takes one file; got {len(files[part.name])}", field=part.name)


def _check_names(files: dict[str, list[Upload]]) -> None:
    """Two files of one part under the same (safe) name: a manifest that lists files by name
    could only ever match one of them, so the other would be silently left out."""
    for field, items in files.items():
        seen: set[str] = set()
        for name, _ in items:
            safe = safe_name(name)
            if safe and safe in seen:
                raise MalformedInputError(f"'{field}' has two files named {safe}", field=field)
            seen.add(safe)


def _explain(error: dict[str, Any], kind: JobKind, form: InputForm) -> dict[str, Any]:
    """An option of another input form is named as such, not as unknown."""
    loc = error.get("loc", ())
    if error.get("type") != "extra_forbidden" or len(loc) != 1:
        return error
    others = [f.name for f in kind.forms if f is not form and loc[0] in f.options.model_fields]
    if others:
        error = error | {"msg": f"does not apply to {form.name} input (an option of {' and '.join(others)} input)"}
        error["type"] = "option_not_applicable"
    return error
