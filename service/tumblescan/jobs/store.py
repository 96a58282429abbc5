"""The job store: every read and write of job state, over the job table (``tables.py``).

Durability lives here, not in the queue (huey delivers at most once): a job is ``queued``
until a worker *claims* it with a conditional update, proves itself alive with a heartbeat
while ``running``, and the reaper re-queues or fails (``worker_lost``) jobs whose heartbeat
stopped. Every transition is a conditional ``UPDATE ... WHERE status = ...`` so two
processes can never both move a job.
"""

from __future__ import annotations

import base64
import json
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from sqlalchemy import Connection, and_, func, or_, select, update

from .tables import STATUSES, Job, create_tables, jobs, make_engine, new_id, workers


class JobStore:
    """All reads and writes of job state."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.engine = make_engine(url)
        create_tables(self.engine)

    @contextmanager
    def _tx(self) -> Iterator[Connection]:
        with self.engine.begin() as conn:
            yield conn

    def close(self) -> None:
        """Drop every pooled connection (before a fork: a connection must never cross one)."""
        self.engine.dispose()

    def ping(self) -> None:
        with self.engine.connect() as conn:
            conn.execute(select(1))

    # Creation and reads.

    def create(
        self, *, kind: str, options: dict[str, Any], input: dict[str, str], owner: str | None, job_id: str | None = None
    ) -> Job:
        job_id = job_id or new_id()
        row = {
            "id": job_id,
            "kind": kind,
            "owner": owner,
            "status": "queued",
            "progress": 0.0,
            "stage": "queued",
            "created_at": time.time(),
            "attempts": 0,
            "cancel_requested": False,
            "options": json.dumps(options),
            "input": json.dumps(input),
            "artifacts": "{}",
            "artifacts_deleted": False,
        }
        with self._tx() as conn:
            conn.execute(jobs.insert().values(**row))
        job = self.get(job_id)
        assert job is not None
        return job

    def get(self, job_id: str, *, owner: str | None = None) -> Job | None:
        q = select(jobs).where(jobs.c.id == job_id)
        if owner is not None:
            q = q.where(jobs.c.owner == owner)
        with self.engine.connect() as conn:
            row = conn.execute(q).first()
        return Job.from_row(row) if row else None

    def list_jobs(
        self, *, status: str | None = None, owner: str | None = None, limit: int = 50, cursor: str | None = None
    ) -> tuple[list[Job], str | None]:
        """Newest first; ``cursor`` continues after the last job of the previous page."""
        q = select(jobs).order_by(jobs.c.created_at.desc(), jobs.c.id.desc()).limit(limit + 1)
        if status is not None:
            q = q.where(jobs.c.status == status)
        if owner is not None:
            q = q.where(jobs.c.owner == owner)
        if cursor is not None:
            created, last_id = decode_cursor(cursor)
            q = q.where(or_(jobs.c.created_at < created, and_(jobs.c.created_at == created, jobs.c.id < last_id)))
        with self.engine.connect() as conn:
            rows = [Job.from_row(r) for r in conn.execute(q)]
        more = len(rows) > limit
        rows = rows[:limit]
        return rows, (encode_cursor(rows[-1]) if more and rows else None)

    def snapshots(self, job_ids: list[str]) -> dict[str, tuple[str, str, float]]:
        """(status, stage, progress) of each job, in one query."""
        q = select(jobs.c.id, jobs.c.status, jobs.c.stage, jobs.c.progress).where(jobs.c.id.in_(job_ids))
        with self.engine.connect() as conn:
            return {r[0]: (r[1], r[2], float(r[3])) for r in conn.execute(q)}

    def counts(self) -> dict[str, int]:
        with self.engine.connect() as conn:
            rows = conn.execute(select(jobs.c.status, func.count()).group_by(jobs.c.status)).all()
        out = dict.fromkeys(STATUSES, 0)
        out.update({r[0]: int(r[1]) for r in rows})
        return out

    def durations(self) -> list[float]:
        """Run time of every finished job that ran (for the metrics histogram)."""
        q = select(jobs.c.finished_at - jobs.c.started_at).where(
            jobs.c.started_at.is_not(None), jobs.c.finished_at.is_not(None)
        )
        with self.engine.connect() as conn:
            return [float(r[0]) for r in conn.execute(q)]

    # Transitions (each conditional on the current status).

    def claim(self, job_id: str, worker: str | None = None) -> Job | None:
        """``queued -> running`` for ``worker``; ``None`` if the job is not queued (any more)."""
        now = time.time()
        with self._tx() as conn:
            done = conn.execute(
                update(jobs)
                .where(jobs.c.id == job_id, jobs.c.status == "queued", jobs.c.cancel_requested.is_(False))
                .values(
                    status="running",
                    started_at=now,
                    heartbeat_at=now,
                    stage="starting",
                    attempts=jobs.c.attempts + 1,
                    worker=worker,
                )
            ).rowcount
        return self.get(job_id) if done else None

    # A run's writes name its attempt (the number ``claim`` gave it): a run that lost its lease and
    # was superseded by a rerun must not overwrite, cancel or delete the rerun's job.

    def heartbeat(self, job_id: str, attempt: int | None = None) -> bool:
        """Refresh the lease; False when the job is no longer ours to run."""
        with self._tx() as conn:
            return bool(
                conn.execute(update(jobs).where(*_running(job_id, attempt)).values(heartbeat_at=time.time())).rowcount
            )

    def progress(self, job_id: str, stage: str, fraction: float, attempt: int | None = None) -> None:
        with self._tx() as conn:
            conn.execute(
                update(jobs)
                .where(*_running(job_id, attempt))
                .values(stage=stage, progress=max(0.0, min(1.0, fraction)), heartbeat_at=time.time())
            )

    def cancel_requested(self, job_id: str, attempt: int | None = None) -> bool:
        """True when the run should stop: cancellation asked, or the job is no longer this run's."""
        with self.engine.connect() as conn:
            q = select(jobs.c.cancel_requested, jobs.c.status, jobs.c.attempts).where(jobs.c.id == job_id)
            row = conn.execute(q).first()
        return row is None or bool(row[0]) or row[1] != "running" or (attempt is not None and row[2] != attempt)

    def succeed(
        self, job_id: str, result: dict[str, Any], artifacts: dict[str, str], attempt: int | None = None
    ) -> bool:
        with self._tx() as conn:
            return bool(
                conn.execute(
                    update(jobs)
                    .where(*_running(job_id, attempt), jobs.c.cancel_requested.is_(False))
                    .values(
                        status="succeeded",
                        progress=1.0,
                        stage="done",
                        finished_at=time.time(),
                        result=json.dumps(result),
                        artifacts=json.dumps(artifacts),
                    )
                ).rowcount
            )

    def fail(
        self,
        job_id: str,
        code: str,
        message: str,
        *,
        from_status: tuple[str, ...] = ("running",),
        attempt: int | None = None,
    ) -> bool:
        with self._tx() as conn:
            return bool(
                conn.execute(
                    update(jobs)
                    .where(jobs.c.id == job_id, jobs.c.status.in_(from_status), *_as_attempt(attempt))
                    .values(
                        status="failed", stage="failed", finished_at=time.time(), error_code=code, error_message=message
                    )
                ).rowcount
            )

    def request_cancel(self, job_id: str) -> Job | None:
        """Queued jobs are cancelled at once; running ones are flagged and stop at their next check."""
        now = time.time()
        with self._tx() as conn:
            conn.execute(
                update(jobs)
                .where(jobs.c.id == job_id, jobs.c.status == "queued")
                .values(status="cancelled", stage="cancelled", finished_at=now, cancel_requested=True)
            )
            conn.execute(
                update(jobs).where(jobs.c.id == job_id, jobs.c.status == "running").values(cancel_requested=True)
            )
        return self.get(job_id)

    def mark_cancelled(self, job_id: str, attempt: int | None = None) -> bool:
        """A running job's worker acknowledges the cancellation."""
        with self._tx() as conn:
            return bool(
                conn.execute(
                    update(jobs)
                    .where(*_running(job_id, attempt))
                    .values(status="cancelled", stage="cancelled", finished_at=time.time())
                ).rowcount
            )

    def requeue(self, job_id: str, *, count_attempt: bool = True) -> bool:
        """``running -> queued`` (an interrupted or lost run). An interruption (graceful
        shutdown) does not count as an attempt."""
        values: dict[str, Any] = {"status": "queued", "stage": "queued", "progress": 0.0, "heartbeat_at": None}
        if not count_attempt:
            values["attempts"] = jobs.c.attempts - 1
        with self._tx() as conn:
            return bool(
                conn.execute(
                    update(jobs).where(jobs.c.id == job_id, jobs.c.status == "running").values(**values)
                ).rowcount
            )

    def stale_running(self, lease_s: float) -> list[Job]:
        cutoff = time.time() - lease_s
        q = select(jobs).where(
            jobs.c.status == "running", or_(jobs.c.heartbeat_at.is_(None), jobs.c.heartbeat_at < cutoff)
        )
        with self.engine.connect() as conn:
            return [Job.from_row(r) for r in conn.execute(q)]

    def reap(self, job: Job, *, max_attempts: int, lease_s: float) -> str | None:
        """Re-queue a job whose worker went silent, or fail it after ``max_attempts`` runs.
        Returns the new status, or None if the job moved meanwhile."""
        cutoff = time.time() - lease_s
        stale = and_(
            jobs.c.id == job.id,
            jobs.c.status == "running",
            or_(jobs.c.heartbeat_at.is_(None), jobs.c.heartbeat_at < cutoff),
        )
        with self._tx() as conn:
            if job.attempts < max_attempts:
                n = conn.execute(
                    update(jobs).where(stale).values(status="queued", stage="queued", progress=0.0, heartbeat_at=None)
                ).rowcount
                return "queued" if n else None
            n = conn.execute(
                update(jobs)
                .where(stale)
                .values(
                    status="failed",
                    stage="failed",
                    finished_at=time.time(),
                    error_code="worker_lost",
                    error_message=f"the worker running this job was lost {job.attempts} time(s)",
                )
            ).rowcount
            return "failed" if n else None

    def queued_older_than(self, age_s: float) -> list[str]:
        q = select(jobs.c.id).where(jobs.c.status == "queued", jobs.c.created_at < time.time() - age_s)
        with self.engine.connect() as conn:
            return [r[0] for r in conn.execute(q)]

    def delete(self, job_id: str) -> None:
        with self._tx() as conn:
            conn.execute(jobs.delete().where(jobs.c.id == job_id))

    def finished_with_artifacts(self) -> list[Job]:
        """Cancelled or failed jobs whose files can go."""
        q = select(jobs).where(jobs.c.status.in_(("cancelled", "failed")), jobs.c.artifacts_deleted.is_(False))
        with self.engine.connect() as conn:
            return [Job.from_row(r) for r in conn.execute(q)]

    def mark_artifacts_deleted(self, job_id: str) -> None:
        with self._tx() as conn:
            conn.execute(update(jobs).where(jobs.c.id == job_id).values(artifacts_deleted=True, artifacts="{}"))

    # Workers.

    def worker_heartbeat(self, worker_id: str, host: str, processes: int) -> None:
        now = time.time()
        with self._tx() as conn:
            n = conn.execute(
                update(workers).where(workers.c.id == worker_id).values(heartbeat_at=now, processes=processes)
            ).rowcount
            if not n:
                conn.execute(workers.insert().values(id=worker_id, host=host, processes=processes, heartbeat_at=now))

    def worker_gone(self, worker_id: str) -> None:
        with self._tx() as conn:
            conn.execute(workers.delete().where(workers.c.id == worker_id))

    def live_worker_processes(self, within_s: float) -> int:
        q = select(func.coalesce(func.sum(workers.c.processes), 0)).where(
            workers.c.heartbeat_at >= time.time() - within_s
        )
        with self.engine.connect() as conn:
            return int(conn.execute(q).scalar_one())


def encode_cursor(job: Job) -> str:
    return base64.urlsafe_b64encode(f"{job.created_at!r}|{job.id}".encode()).decode().rstrip("=")


def decode_cursor(cursor: str) -> tuple[float, str]:
    try:
        raw = base64.urlsafe_b64decode(cursor + "=" * (-len(cursor) % 4)).decode()
        created, job_id = raw.split("|", 1)
        return float(created), job_id
    except (ValueError, UnicodeDecodeError):
        raise ValueError("cursor is not one this service issued") from None


def _running(job_id: str, attempt: int | None) -> list[Any]:
    """The job is running, and (when ``attempt`` is given) as that attempt."""
    return [jobs.c.id == job_id, jobs.c.status == "running", *_as_attempt(attempt)]


def _as_attempt(attempt: int | None) -> list[Any]:
    """The fence of a run's writes: no condition without an attempt number."""
    return [] if attempt is None else [jobs.c.attempts == attempt]
