"""Real Redis and PostgreSQL on localhost for the scale-out tests: used if running, started
if installed, and otherwise the tests skip saying why."""

from __future__ import annotations

import shutil
import subprocess
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

REDIS_URL = "redis://127.0.0.1:6379/0"
PG_ADMIN = "postgresql://postgres@127.0.0.1:5432/postgres"


def redis_up() -> bool:
    import redis

    try:
        return bool(redis.Redis.from_url(REDIS_URL, socket_timeout=1).ping())
    except redis.RedisError:
        return False


def ensure_redis() -> None:
    if redis_up():
        return
    if not shutil.which("redis-server"):
        pytest.skip("Redis is not running on 127.0.0.1:6379 and redis-server is not installed")
    Path("/tmp/tumblescan-redis").mkdir(exist_ok=True)
    subprocess.run(
        [
            "redis-server",
            "--daemonize",
            "yes",
            "--bind",
            "127.0.0.1",
            "--port",
            "6379",
            "--save",
            "",
            "--appendonly",
            "no",
            "--dir",
            "/tmp/tumblescan-redis",
        ],
        check=False,
    )
    _wait(redis_up, "Redis")


def pg_up() -> bool:
    import psycopg

    try:
        with psycopg.connect(PG_ADMIN, connect_timeout=2):
            return True
    except psycopg.Error:
        return False


def ensure_postgres() -> None:
    if pg_up():
        return
    clusters = Path("/etc/postgresql")
    if not shutil.which("pg_ctlcluster") or not clusters.is_dir():
        pytest.skip("PostgreSQL is not running on 127.0.0.1:5432 and no cluster is installed to start")
    for version in clusters.iterdir():
        subprocess.run(["pg_ctlcluster", "--skip-systemctl-redirect", version.name, "main", "start"], check=False)
    _wait(pg_up, "PostgreSQL")


@contextmanager
def postgres_database() -> Iterator[str]:
    """A fresh database, dropped afterwards; yields its SQLAlchemy URL."""
    import psycopg

    ensure_postgres()
    name = f"tumblescan_test_{uuid.uuid4().hex[:10]}"
    with psycopg.connect(PG_ADMIN, autocommit=True) as conn:
        conn.execute(f'CREATE DATABASE "{name}"')
    try:
        yield f"postgresql+psycopg://postgres@127.0.0.1:5432/{name}"
    finally:
        with psycopg.connect(PG_ADMIN, autocommit=True) as conn:
            conn.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')


def _wait(check: object, what: str, timeout_s: float = 30) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if check():  # type: ignore[operator]
            return
        time.sleep(0.3)
    pytest.skip(f"{what} could not be started")


def scaleout_env(db_url: str, artifacts: Path, **extra: str) -> dict[str, str]:
    """Settings shared by an API and its workers in scale-out mode (a queue name of their own)."""
    return {
        "TUMBLESCAN_REDIS_URL": REDIS_URL,
        "TUMBLESCAN_DATABASE_URL": db_url,
        "TUMBLESCAN_QUEUE_NAME": f"test-{uuid.uuid4().hex[:8]}",
        "TUMBLESCAN_ARTIFACT_DIR": str(artifacts),
        **extra,
    }
