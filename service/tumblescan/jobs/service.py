"""The job service: what the HTTP API and the CLI do with jobs, over store, artifacts and queue."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any, BinaryIO

from pydantic import ValidationError

from ..errors import InputError
from .kinds import FinishedJob, Limits, get_kind, kind_names
from .runtime import Runtime
from .store import FINAL, Job, new_id

log = logging.getLogger("tumblescan.service")
REPORT_FILE = "report.html"


class QueueUnavailableError(Exception):
    """The queue could not take the job; nothing was kept. Retry later."""


class UnknownKindError(InputError):
    code = "unknown_kind"


class OptionsError(Exception):
    """Options failed validation; ``errors`` are pydantic's, each naming its option."""

    def __init__(self, errors: list[dict[str, Any]]) -> None:
        super().__init__("invalid options")
        self.errors = errors


class JobService:
    def __init__(self, rt: Runtime, enqueue: Callable[[str], Any], pending: Callable[[], int]) -> None:
        self.rt = rt
        self.store = rt.store
        self.artifacts = rt.artifacts
        self._enqueue = enqueue
        self._pending = pending
        s = rt.settings
        self.limits = Limits(max_observations=s.max_observations, max_cloud_points=s.max_cloud_points)

    # Submission.

    def submit_json(self, kind_name: str, payload: Any, options: dict[str, Any], owner: str | None) -> Job:
        kind, opts = self._kind_and_options(kind_name, options)
        job_id = new_id()
        try:
            inputs = kind.accept_json(
                payload, lambda name, data: self.artifacts.save_bytes(job_id, name, data), self.limits
            )
        except BaseException:
            self.artifacts.delete(job_id)
            raise
        return self._create_and_enqueue(job_id, kind_name, opts, inputs, owner)

    def submit_upload(
        self, kind_name: str, files: dict[str, BinaryIO], options: dict[str, Any], owner: str | None
    ) -> Job:
        kind, opts = self._kind_and_options(kind_name, options)
        job_id = new_id()
        try:
            stored = {
                field: self.artifacts.save_stream(
                    job_id, f"upload-{field}", src, max_bytes=self.rt.settings.max_upload_bytes
                )
                for field, src in files.items()
            }
            inputs = kind.accept_files(stored, self.limits, opts)
        except BaseException:
            self.artifacts.delete(job_id)
            raise
        return self._create_and_enqueue(job_id, kind_name, opts, inputs, owner)

    def _kind_and_options(self, kind_name: str, options: dict[str, Any]) -> tuple[Any, dict[str, Any]]:
        try:
            kind = get_kind(kind_name)
        except KeyError:
            raise UnknownKindError(
                f"unknown job kind {kind_name!r}; known: {', '.join(kind_names())}", field="kind"
            ) from None
        try:
            opts = kind.options_model.model_validate(options)
        except ValidationError as exc:
            raise OptionsError([dict(e) for e in exc.errors(include_url=False, include_input=False)]) from None
        return kind, opts.model_dump(mode="json", exclude_unset=True)

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
        """The succeeded job's report, built and stored on first request."""
        path = self.artifacts.path(job.id, REPORT_FILE)
        if not path.exists():
            finished = FinishedJob(
                id=job.id,
                result=job.result or {},
                options=job.options,
                inputs={k: self.artifacts.path(job.id, v) for k, v in job.input.items()},
                artifacts={k: self.artifacts.path(job.id, v) for k, v in job.artifacts.items()},
            )
            self.artifacts.save_bytes(job.id, REPORT_FILE, get_kind(job.kind).report(finished).encode("utf-8"))
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
