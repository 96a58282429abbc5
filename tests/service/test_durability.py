"""Nothing lost: jobs survive a restart of the service, and a killed worker's job runs again."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import httpx
import pytest

from tumblescan import tracks_to_json
from tumblescan.jobs.store import JobStore

from ..conftest import tracks_for
from ..live import serve, wait_job

pytestmark = pytest.mark.slow
FINAL = ("succeeded", "failed", "cancelled")
# A few seconds of swarm search: long enough to be caught running.
SLOWISH = {"strategy": "swarm", "max_attempts": 1, "swarm": {"particles": 400, "iterations": 200}}


def submit(http: httpx.Client, seed: int, options: dict[str, object]) -> str:
    r = http.post("/v1/jobs", json={"input": {"tracks": tracks_to_json(tracks_for(seed)[1])}, "options": options})
    assert r.status_code == 202, r.text
    return str(r.json()["id"])


def wait_status(http: httpx.Client, job_id: str, statuses: tuple[str, ...], timeout_s: float) -> dict[str, object]:
    return wait_job(http, job_id, statuses=statuses, timeout_s=timeout_s)


def test_queued_and_running_jobs_survive_a_restart(tmp_path: Path) -> None:
    data = tmp_path / "data"
    with serve(data, workers=1) as url, httpx.Client(base_url=url, timeout=30) as http:
        ids = [submit(http, 80 + i, SLOWISH) for i in range(4)]
        wait_status(http, ids[0], ("running",), 60)
    # Stopped mid-job: the running job went back to the queue, nothing is left running.
    store = JobStore(f"sqlite:///{data / 'jobs.db'}")
    statuses = {store.get(i).status for i in ids}  # type: ignore[union-attr]
    assert "running" not in statuses and statuses <= {"queued", "succeeded"}
    with serve(data, workers=1) as url, httpx.Client(base_url=url, timeout=30) as http:
        done = [wait_status(http, i, FINAL, 180) for i in ids]
    assert [d["status"] for d in done] == ["succeeded"] * 4
    # An interruption by shutdown is not counted as a failed attempt.
    assert all(store.get(i).attempts == 1 for i in ids)  # type: ignore[union-attr]


def test_a_job_whose_worker_is_killed_runs_again_on_another(tmp_path: Path) -> None:
    env = {"TUMBLESCAN_LEASE_S": "3", "TUMBLESCAN_HEARTBEAT_S": "0.5", "TUMBLESCAN_REAPER_INTERVAL_S": "0.5"}
    data = tmp_path / "data"
    with serve(data, workers=2, extra_env=env) as url, httpx.Client(base_url=url, timeout=30) as http:
        job_id = submit(http, 90, SLOWISH)
        wait_status(http, job_id, ("running",), 60)
        store = JobStore(f"sqlite:///{data / 'jobs.db'}")
        victim = store.get(job_id).worker  # type: ignore[union-attr]
        assert victim is not None
        os.kill(int(victim.rsplit(":", 1)[1]), signal.SIGKILL)
        done = wait_status(http, job_id, FINAL, 180)
        assert done["status"] == "succeeded"
        job = store.get(job_id)
        assert job is not None and job.attempts == 2 and job.worker != victim


def test_a_job_whose_last_attempt_dies_fails_as_worker_lost(tmp_path: Path) -> None:
    env = {
        "TUMBLESCAN_LEASE_S": "3",
        "TUMBLESCAN_HEARTBEAT_S": "0.5",
        "TUMBLESCAN_REAPER_INTERVAL_S": "0.5",
        "TUMBLESCAN_MAX_ATTEMPTS": "1",
    }
    data = tmp_path / "data"
    with serve(data, workers=2, extra_env=env) as url, httpx.Client(base_url=url, timeout=30) as http:
        job_id = submit(http, 91, SLOWISH)
        wait_status(http, job_id, ("running",), 60)
        worker = JobStore(f"sqlite:///{data / 'jobs.db'}").get(job_id).worker  # type: ignore[union-attr]
        os.kill(int(str(worker).rsplit(":", 1)[1]), signal.SIGKILL)
        done = wait_status(http, job_id, FINAL, 60)
        assert done["status"] == "failed" and done["error"]["code"] == "worker_lost"  # type: ignore[index]
        # The pool recovers: the next job runs.
        assert wait_status(http, submit(http, 92, {}), FINAL, 120)["status"] == "succeeded"


def test_a_running_job_whose_files_vanish_fails_clearly(tmp_path: Path) -> None:
    import json

    import numpy as np

    from tumblescan import TimedCloud, write_ply

    data = tmp_path / "data"
    cloud = tmp_path / "c.ply"
    write_ply(cloud, TimedCloud(np.random.default_rng(0).normal(size=(1000, 3)) + [0, 0, 50], np.linspace(0, 14, 1000)))
    tracks = json.dumps(tracks_to_json(tracks_for(93)[1])).encode()
    with serve(data, workers=1) as url, httpx.Client(base_url=url, timeout=30) as http:
        files = {"file": ("t.json", tracks), "cloud": ("c.ply", cloud.read_bytes())}
        job_id = http.post("/v1/jobs/upload", files=files, data={"options": json.dumps(SLOWISH)}).json()["id"]
        wait_status(http, job_id, ("running",), 60)
        job_dir = data / "artifacts" / job_id
        job_dir.rename(tmp_path / "gone")
        job_dir.write_text("the directory is gone")  # writes under it fail, even for root
        done = wait_status(http, job_id, FINAL, 120)
        assert done["status"] == "failed" and done["error"]["code"] == "storage_error"  # type: ignore[index]
        assert http.get("/healthz").status_code == 200
