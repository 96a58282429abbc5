"""Redis restarted under load in scale-out mode: submissions get a retryable 503 while it is
down, and jobs queued before it went down (their queue entries lost with it) still complete."""

from __future__ import annotations

import shutil
import subprocess
import time
from pathlib import Path

import httpx
import pytest

from tumblescan import tracks_to_json

from ..conftest import tracks_for
from ..live import free_port, serve, spawn, stop, wait_job, wait_ready

pytestmark = pytest.mark.slow


def start_redis(port: int, workdir: Path) -> subprocess.Popen[bytes]:
    """A private, non-persistent Redis: a restart loses every queued task, the worst case."""
    server = shutil.which("redis-server")
    if server is None:
        pytest.skip("redis-server is not installed")
    cmd = [
        server,
        "--port",
        str(port),
        "--bind",
        "127.0.0.1",
        "--save",
        "",
        "--appendonly",
        "no",
        "--dir",
        str(workdir),
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 20
    import redis

    while time.monotonic() < deadline:
        try:
            if redis.Redis(port=port, socket_timeout=0.5).ping():
                return proc
        except redis.RedisError:
            time.sleep(0.1)
    raise AssertionError("private redis did not start")


def test_submissions_get_503_while_redis_is_down_and_queued_jobs_complete_after(tmp_path: Path) -> None:
    port = free_port()
    redis_proc = start_redis(port, tmp_path)
    env = {
        "TUMBLESCAN_REDIS_URL": f"redis://127.0.0.1:{port}/0",
        "TUMBLESCAN_DATABASE_URL": f"sqlite:///{tmp_path / 'jobs.db'}",
        "TUMBLESCAN_ARTIFACT_DIR": str(tmp_path / "artifacts"),
        "TUMBLESCAN_REAPER_INTERVAL_S": "0.5",
    }
    body = {"input": {"tracks": tracks_to_json(tracks_for(110)[1])}}
    worker = None
    try:
        with (
            serve(tmp_path / "api", extra_env=env, args=["--no-workers"]) as url,
            httpx.Client(base_url=url, timeout=30) as http,
        ):
            # Jobs queued while no worker runs, then Redis restarts and loses them all.
            queued = [http.post("/v1/jobs", json=body).json()["id"] for _ in range(5)]
            stop(redis_proc)
            r = http.post("/v1/jobs", json=body)
            assert (
                r.status_code == 503 and r.headers["retry-after"] and r.json()["detail"]["code"] == "queue_unavailable"
            )
            assert http.get("/readyz").status_code == 503
            assert http.get("/healthz").status_code == 200
            redis_proc = start_redis(port, tmp_path)
            worker = spawn(
                ["worker", "--workers", "1"], {**env, "TUMBLESCAN_DATA_DIR": str(tmp_path / "w")}, tmp_path / "w.log"
            )
            wait_ready(url, worker, tmp_path / "w.log")
            later = http.post("/v1/jobs", json=body)
            assert later.status_code == 202
            for job_id in [*queued, later.json()["id"]]:
                assert wait_job(http, job_id)["status"] == "succeeded"
    finally:
        if worker is not None:
            stop(worker)
        stop(redis_proc)
