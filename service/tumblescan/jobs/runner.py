"""Running one job inside a worker: claim, heartbeat, progress, result, and every way out."""

from __future__ import annotations

import logging
import os
import socket
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

from pydantic import ValidationError
from sqlalchemy.exc import OperationalError

from ..errors import InputError
from .kind import JobCancelledError, JobContext
from .registry import get_kind
from .runtime import Runtime

log = logging.getLogger("tumblescan.worker")


class JobTimeoutError(Exception):
    """The job outran ``job_timeout_s``; raised at its next progress report."""


# Progress is written at most this often; cancellation is still checked at every report.
PROGRESS_INTERVAL_S = 0.2
# How long a finished job waits for an unreachable store before giving up its result; past this
# the lease lapses and the reaper runs the job again, so nothing is lost either way.
STORE_PATIENCE_S = 120.0

T = TypeVar("T")

# Set in a worker process when the consumer interrupts it to shut down (jobs.queue notes the
# signal). Huey stops the running job by raising KeyboardInterrupt in it, and a library may turn
# that into an error of its own: pydantic-core, interrupted while building a model's schema,
# raised SchemaError, and the job failed instead of going back to the queue.
SHUTTING_DOWN = threading.Event()


def _interrupted(exc: BaseException) -> bool:
    """Whether ``exc`` came of the shutdown interrupt: a KeyboardInterrupt in its chain of causes,
    or raised after :data:`SHUTTING_DOWN` was set."""
    visited: set[int] = set()  # a chain of causes set by hand may loop
    cause: BaseException | None = exc
    while cause is not None and id(cause) not in visited:
        if isinstance(cause, KeyboardInterrupt):
            return True
        visited.add(id(cause))
        cause = cause.__cause__ or cause.__context__
    return SHUTTING_DOWN.is_set()


def _patiently(write: Callable[[], T], what: str) -> T:
    """``write()``, retried with backoff while the store is unreachable (a restart, a failover)."""
    deadline = time.monotonic() + STORE_PATIENCE_S
    pause_s = 0.5
    while True:
        try:
            return write()
        except OperationalError:
            if time.monotonic() + pause_s > deadline:
                raise
            log.warning("the store is unreachable while %s; retrying in %.1f s", what, pause_s)
            time.sleep(pause_s)
            pause_s = min(2 * pause_s, 5.0)


class _Lease(threading.Thread):
    """Heartbeat thread: keeps the job's lease fresh and notices cancellation."""

    def __init__(self, rt: Runtime, job_id: str, attempt: int) -> None:
        super().__init__(daemon=True, name=f"lease-{job_id}")
        self.rt, self.job_id, self.attempt = rt, job_id, attempt
        self.cancelled = threading.Event()
        self.stopped = threading.Event()

    def run(self) -> None:
        while not self.stopped.wait(self.rt.settings.heartbeat_s):
            try:
                store, job_id, attempt = self.rt.store, self.job_id, self.attempt
                if not store.heartbeat(job_id, attempt) or store.cancel_requested(job_id, attempt):
                    self.cancelled.set()
            except Exception:  # a store hiccup must not kill the job; the next beat retries
                log.exception("heartbeat of job %s failed", self.job_id)


def run_job(rt: Runtime, job_id: str) -> str | None:
    """Run ``job_id`` if it is still queued; returns its final status, or None when the job is not
    (or no longer) this run's: not queued, superseded by a rerun after a lost lease, or the store
    stayed unreachable at the end (the reaper then runs it again)."""
    job = rt.store.claim(job_id, worker=f"{socket.gethostname()}:{os.getpid()}")
    if job is None:
        return None
    attempt = job.attempts
    lease = _Lease(rt, job_id, attempt)
    lease.start()
    last_write = [0.0]
    deadline = time.monotonic() + rt.settings.job_timeout_s

    def report(stage: str, fraction: float) -> None:
        if lease.cancelled.is_set():
            raise JobCancelledError
        if time.monotonic() > deadline:
            raise JobTimeoutError(f"the job ran longer than its limit of {rt.settings.job_timeout_s:g} s (at {stage})")
        now = time.monotonic()
        if now - last_write[0] >= PROGRESS_INTERVAL_S:
            last_write[0] = now
            try:
                rt.store.progress(job_id, stage, fraction, attempt)
                cancelled = rt.store.cancel_requested(job_id, attempt)
            except OperationalError:  # progress is a courtesy: an outage must not cost the job
                log.warning("progress of job %s not written: the store is unreachable", job_id)
                cancelled = False
            if cancelled:
                lease.cancelled.set()
                raise JobCancelledError

    def output_path(name: str) -> Path:
        return rt.artifacts.temporary(job_id, name)

    try:
        kind = get_kind(job.kind)
        inputs = {k: rt.artifacts.path(job_id, v) for k, v in job.input.items()}
        out = kind.run(JobContext(job_id, job.options, inputs, output_path, report))
        report("saving", 0.99)
        for file_name in out.artifacts.values():
            rt.artifacts.publish(job_id, file_name)
        if _patiently(lambda: rt.store.succeed(job_id, out.result, out.artifacts, attempt), f"saving job {job_id}"):
            return "succeeded"
        raise JobCancelledError  # cancelled (or superseded) between the last check and the result
    except JobTimeoutError as exc:
        return _failed(rt, job_id, attempt, "timeout", str(exc))
    except JobCancelledError:
        return _cancelled(rt, job_id, attempt)
    except InputError as exc:
        return _failed(rt, job_id, attempt, exc.code, str(exc))
    except ValidationError as exc:
        if not exc.title.endswith("Options"):  # a result or an internal model: our fault
            log.exception("job %s failed", job_id)
            return _failed(rt, job_id, attempt, "internal_error", f"{type(exc).__name__}: {exc}")
        # Stored options this version refuses (a job queued before an upgrade made them stricter):
        # the caller's to change, as they would have been told at submission.
        e = exc.errors(include_url=False)[0]
        where = ".".join(map(str, ("options", *e["loc"])))
        return _failed(rt, job_id, attempt, "invalid_options", f"{where}: {e['msg']}")
    except OperationalError:
        # The store went away at a write that cannot be skipped; the lease lapses and the reaper
        # runs the job again once the store is back, instead of the job ending as our fault.
        log.exception("job %s left to the reaper: the store is unreachable", job_id)
        return None
    except Exception as exc:
        if _interrupted(exc):
            # Out as the interrupt it was: huey's signal puts the job back in the queue.
            raise KeyboardInterrupt from exc
        if isinstance(exc, OSError):
            log.exception("job %s failed on storage", job_id)
            return _failed(rt, job_id, attempt, "storage_error", f"{type(exc).__name__}: {exc}")
        log.exception("job %s failed", job_id)
        return _failed(rt, job_id, attempt, "internal_error", f"{type(exc).__name__}: {exc}")
    finally:
        lease.stopped.set()


def _failed(rt: Runtime, job_id: str, attempt: int, code: str, message: str) -> str | None:
    try:
        if _patiently(lambda: rt.store.fail(job_id, code, message, attempt=attempt), f"failing job {job_id}"):
            return "failed"
    except OperationalError:
        log.exception("job %s left to the reaper: its failure could not be recorded", job_id)
    return None  # superseded, cancelled meanwhile, or the store stayed away: not this run's to set


def _cancelled(rt: Runtime, job_id: str, attempt: int) -> str | None:
    try:
        if not _patiently(lambda: rt.store.mark_cancelled(job_id, attempt), f"cancelling job {job_id}"):
            # Not cancelled but superseded: a rerun owns the job (and its files) now.
            log.warning("job %s was taken over by a rerun; attempt %d stops", job_id, attempt)
            return None
    except OperationalError:
        log.exception("job %s left to the reaper: its cancellation could not be recorded", job_id)
        return None
    rt.artifacts.delete(job_id)
    try:
        _patiently(lambda: rt.store.mark_artifacts_deleted(job_id), f"cancelling job {job_id}")
    except OperationalError:  # the files are gone and the job is cancelled; only the flag is late
        log.exception("job %s: its files are deleted but could not be marked so", job_id)
    return "cancelled"
