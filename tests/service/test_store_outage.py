"""PostgreSQL restarted under load in scale-out mode: submissions get a retryable 503 while
it is down, and every job accepted before or after completes once it is back."""

from __future__ import annotations

import shutil
import subprocess
import threading
import time
from pathlib import Path

import httpx
import pytest

from tumblescan import tracks_to_json

from ..conftest import tracks_for
from ..infra import ensure_redis, pg_up, postgres_database, scaleout_env
from ..live import serve, spawn, stop, wait_job, wait_ready

pytestmark = pytest.mark.slow


def pg_ctl(action: str) -> None:
    clusters = Path("/etc/postgresql")
    for version in clusters.iterdir():
        subprocess.run(
            ["pg_ctlcluster", "--skip-systemctl-redirect", version.name, "main", action], check=True, timeout=120
        )


def test_submissions_get_503_while_postgres_restarts_and_all_jobs_complete(tmp_path: Path) -> None:
    if not shutil.which("pg_ctlcluster") or not Path("/etc/postgresql").is_dir():
        pytest.skip("no local PostgreSQL cluster this test may restart")
    ensure_redis()
    with postgres_database() as db_url:
        env = scaleout_env(db_url, tmp_path / "shared", TUMBLESCAN_LEASE_S="5", TUMBLESCAN_REAPER_INTERVAL_S="0.5")
        worker = spawn(
            ["worker", "--workers", "2"], {**env, "TUMBLESCAN_DATA_DIR": str(tmp_path / "w")}, tmp_path / "w.log"
        )
        body = {"input": {"tracks": tracks_to_json(tracks_for(120)[1])}}
        accepted: list[str] = []
        statuses: list[int] = []
        stop_load = threading.Event()
        try:
            with serve(tmp_path / "api", extra_env=env, args=["--no-workers"]) as url:
                wait_ready(url, worker, tmp_path / "w.log")

                def load() -> None:
                    with httpx.Client(base_url=url, timeout=30) as http:
                        while not stop_load.is_set():
                            r = http.post("/v1/jobs", json=body)
                            statuses.append(r.status_code)
                            if r.status_code == 202:
                                accepted.append(r.json()["id"])
                            else:
                                assert r.status_code == 503 and r.headers.get("retry-after"), r.text
                            time.sleep(0.05)

                loader = threading.Thread(target=load)
                loader.start()
                time.sleep(2)
                pg_ctl("stop")
                time.sleep(3)
                pg_ctl("start")
                deadline = time.monotonic() + 60
                while not pg_up():
                    assert time.monotonic() < deadline
                    time.sleep(0.2)
                time.sleep(3)
                stop_load.set()
                loader.join()
                assert 503 in statuses and statuses[-1] == 202
                with httpx.Client(base_url=url, timeout=30) as http:
                    for job_id in accepted:
                        done = wait_job(http, job_id, timeout_s=240)
                        assert done["status"] == "succeeded", (done["status"], done.get("error"), done.get("attempts"))
        finally:
            stop_load.set()
            if not pg_up():
                pg_ctl("start")
            stop(worker)
