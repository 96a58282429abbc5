"""The job table: the SQLAlchemy Core schema of jobs and workers, the ``Job`` row model, and
the engine behind them (SQLite by default, in WAL mode so several processes share the file;
PostgreSQL by URL). ``create_tables`` tolerates processes racing to create the same tables.
Every read and write of job state goes through the store (``store.py``).
"""

from __future__ import annotations

import json
import time
import uuid
from dataclasses import dataclass
from typing import Any

from sqlalchemy import (
    Boolean,
    Column,
    Engine,
    Float,
    Index,
    Integer,
    MetaData,
    String,
    Table,
    Text,
    create_engine,
    event,
)
from sqlalchemy.exc import IntegrityError, OperationalError, ProgrammingError

STATUSES = ("queued", "running", "succeeded", "failed", "cancelled")
FINAL = ("succeeded", "failed", "cancelled")

metadata = MetaData()
jobs = Table(
    "jobs",
    metadata,
    Column("id", String(32), primary_key=True),
    Column("kind", String(64), nullable=False),
    Column("owner", String(64), nullable=True),
    Column("status", String(16), nullable=False),
    Column("progress", Float, nullable=False, default=0.0),
    Column("stage", String(64), nullable=False, default="queued"),
    Column("created_at", Float, nullable=False),
    Column("started_at", Float),
    Column("finished_at", Float),
    Column("heartbeat_at", Float),
    Column("attempts", Integer, nullable=False, default=0),
    Column("cancel_requested", Boolean, nullable=False, default=False),
    Column("worker", String(128)),
    Column("error_code", String(64)),
    Column("error_message", Text),
    Column("options", Text, nullable=False),
    Column("input", Text, nullable=False),
    Column("result", Text),
    Column("artifacts", Text, nullable=False, default="{}"),
    Column("artifacts_deleted", Boolean, nullable=False, default=False),
    Index("ix_jobs_created", "created_at", "id"),
    Index("ix_jobs_status", "status"),
)
workers = Table(
    "workers",
    metadata,
    Column("id", String(64), primary_key=True),
    Column("host", String(255), nullable=False),
    Column("processes", Integer, nullable=False),
    Column("heartbeat_at", Float, nullable=False),
)


@dataclass(frozen=True)
class Job:
    """A job row. ``input`` and ``artifacts`` map names to stored file paths."""

    id: str
    kind: str
    owner: str | None
    status: str
    progress: float
    stage: str
    created_at: float
    started_at: float | None
    finished_at: float | None
    heartbeat_at: float | None
    attempts: int
    cancel_requested: bool
    worker: str | None
    error_code: str | None
    error_message: str | None
    options: dict[str, Any]
    input: dict[str, str]
    result: dict[str, Any] | None
    artifacts: dict[str, str]
    artifacts_deleted: bool

    @classmethod
    def from_row(cls, row: Any) -> Job:
        m = row._mapping
        return cls(
            **{k: m[k] for k in m if k not in ("options", "input", "result", "artifacts")},
            options=json.loads(m["options"]),
            input=json.loads(m["input"]),
            result=json.loads(m["result"]) if m["result"] else None,
            artifacts=json.loads(m["artifacts"] or "{}"),
        )


def new_id() -> str:
    return uuid.uuid4().hex


def create_tables(engine: Engine, tries: int = 5) -> None:
    """``create_all`` tolerant of other processes creating the same tables at the same time."""
    for attempt in range(tries):
        try:
            metadata.create_all(engine)
            return
        except (IntegrityError, ProgrammingError, OperationalError):
            if attempt == tries - 1:
                raise
            time.sleep(0.2 * (attempt + 1))


def make_engine(url: str) -> Engine:
    if url.startswith("sqlite"):
        engine = create_engine(url, connect_args={"timeout": 30, "check_same_thread": False})

        @event.listens_for(engine, "connect")
        def _sqlite_pragmas(dbapi_conn: Any, _: Any) -> None:
            # WAL lets the API read while workers write; several processes share the file.
            cur = dbapi_conn.cursor()
            cur.execute("PRAGMA journal_mode=WAL")
            cur.execute("PRAGMA synchronous=NORMAL")
            cur.execute("PRAGMA busy_timeout=30000")
            cur.close()

        return engine
    return create_engine(url, pool_pre_ping=True, pool_size=5, max_overflow=10)
