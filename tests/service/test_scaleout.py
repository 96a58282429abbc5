"""Scale-out mode: an API process (no workers) and two worker processes sharing PostgreSQL,
Redis and an artifact directory finish a batch of jobs."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from tumblescan import tracks_to_json
from tumblescan.jobs.store import JobStore
from tumblescan_client import Client

from ..conftest import tracks_for
from ..infra import ensure_redis, postgres_database, scaleout_env
from ..live import serve, spawn, stop, wait_ready

pytestmark = pytest.mark.slow


def test_api_and_two_workers_on_redis_and_postgres_finish_a_batch(tmp_path: Path) -> None:
    ensure_redis()
    with postgres_database() as db_url:
        env = scaleout_env(db_url, tmp_path / "shared-artifacts")
        workers = [
            spawn(
                ["worker", "--workers", "1"],
                {**env, "TUMBLESCAN_DATA_DIR": str(tmp_path / f"w{i}")},
                tmp_path / f"w{i}.log",
            )
            for i in range(2)
        ]
        try:
            with serve(tmp_path / "api", extra_env=env, args=["--no-workers"]) as url:
                wait_ready(url, workers[0], tmp_path / "w0.log")
                tracks = [tracks_to_json(tracks_for(60 + i)[1]) for i in range(4)]
                with Client(url) as client:
                    # Both worker machines report in (their heartbeats start independently).
                    deadline = time.monotonic() + 60
                    while client._http.get("/readyz").json()["checks"]["workers"] != "2 process(es)":
                        assert time.monotonic() < deadline, "the two workers never both reported"
                        time.sleep(0.2)
                    jobs = [client.jobs.create(tracks=tracks[i % 4], options={"seed": i}) for i in range(20)]
                    results = [client.jobs.wait(j.id, timeout=180) for j in jobs]
                assert [r.status for r in results] == ["succeeded"] * 20
                ran_on = {JobStore(db_url).get(j.id).worker for j in jobs}  # type: ignore[union-attr]
                assert 1 <= len(ran_on) <= 2 and None not in ran_on
        finally:
            for w in workers:
                stop(w)
