"""Running one job inside a worker: claim, heartbeat, progress, result, and every way out."""

from __future__ import annotations

import logging
import os
import socket
import threading
import time
from pathlib import Path

from ..errors import InputError
from .kind import JobCancelledError, JobContext
from .registry import get_kind
from .runtime import Runtime

log = logging.getLogger("tumblescan.worker")


class JobTimeoutError(Exception):
    """The job outran ``job_timeout_s``; raised at its next progress report."""


# Progress is written at most this often; cancellation is still checked at every report.
PROGRESS_INTERVAL_S = 0.2


class _Lease(threading.Thread):
    """Heartbeat thread: keeps the job's lease fresh and notices cancellation."""

    def __init__(self, rt: Runtime, job_id: str) -> None:
        super().__init__(daemon=True, name=f"lease-{job_id}")
        self.rt, self.job_id = rt, job_id
        self.cancelled = threading.Event()
        self.stopped = threading.Event()

    def run(self) -> None:
        while not self.stopped.wait(self.rt.settings.heartbeat_s):
            try:
                if not self.rt.store.heartbeat(self.job_id) or self.rt.store.cancel_requested(self.job_id):
                    self.cancelled.set()
            except Exception:  # a store hiccup must not kill the job; the next beat retries
                log.exception("heartbeat of job %s failed", self.job_id)


def run_job(rt: Runtime, job_id: str) -> str | None:
    """Run ``job_id`` if it is still queued; returns its final status (None if not ours)."""
    job = rt.store.claim(job_id, worker=f"{socket.gethostname()}:{os.getpid()}")
    if job is None:
        return None
    lease = _Lease(rt, job_id)
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
            rt.store.progress(job_id, stage, fraction)
            if rt.store.cancel_requested(job_id):
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
        if rt.store.succeed(job_id, out.result, out.artifacts):
            return "succeeded"
        raise JobCancelledError  # cancelled between the last check and the result
    except JobTimeoutError as exc:
        rt.store.fail(job_id, "timeout", str(exc))
        return "failed"
    except JobCancelledError:
        rt.store.mark_cancelled(job_id)
        rt.artifacts.delete(job_id)
        rt.store.mark_artifacts_deleted(job_id)
        return "cancelled"
    except InputError as exc:
        rt.store.fail(job_id, exc.code, str(exc))
        return "failed"
    except OSError as exc:
        log.exception("job %s failed on storage", job_id)
        rt.store.fail(job_id, "storage_error", f"{type(exc).__name__}: {exc}")
        return "failed"
    except Exception as exc:
        log.exception("job %s failed", job_id)
        rt.store.fail(job_id, "internal_error", f"{type(exc).__name__}: {exc}")
        return "failed"
    finally:
        lease.stopped.set()
