"""What the API answers about jobs it holds, in the corners a user's review found: a finished
job's files gone from the store, a cancellation under way, the file name a download is saved
as, readiness, the pages' keys. In-process (FastAPI's TestClient, no workers): jobs are made
in the store as a worker would leave them."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from tumblescan import TimedCloud, write_ply
from tumblescan.api.app import create_app
from tumblescan.jobs.service import JobService
from tumblescan.jobs.tables import Job
from tumblescan.settings import Settings


@pytest.fixture
def client(api: TestClient) -> TestClient:
    return api


def service_of(client: TestClient) -> JobService:
    service: JobService = client.app.state.service  # type: ignore[attr-defined]
    return service


def detail(r: Any, status: int) -> dict[str, Any]:
    assert r.status_code == status, r.text
    body: dict[str, Any] = r.json()["detail"]
    return body


def succeeded_linescan_job(client: TestClient) -> Job:
    """A succeeded linescan-motion job with its tracks input and rectified cloud stored."""
    service = service_of(client)
    job = service.store.create(kind="linescan-motion", options={}, input={"tracks": "input-tracks.json"}, owner=None)
    service.artifacts.save_bytes(job.id, "input-tracks.json", b'{"observations": []}')
    write_ply(service.artifacts.path(job.id, "cloud.ply"), TimedCloud(np.zeros((4, 3)), np.arange(4.0)))
    service.store.claim(job.id)
    assert service.store.succeed(job.id, {}, {"cloud": "cloud.ply"})
    return job


def saved_as(r: Any) -> str:
    match = re.search(r'filename="([^"]+)"', r.headers.get("content-disposition", ""))
    assert match, r.headers
    return match.group(1)


def test_a_finished_jobs_file_gone_from_the_store_is_410_naming_it(client: TestClient) -> None:
    job = succeeded_linescan_job(client)
    service_of(client).artifacts.path(job.id, "cloud.ply").unlink()  # removed by hand, or lost
    for path in ("cloud", "artifacts/cloud"):
        for params in ({}, {"format": "npz"}):
            d = detail(client.get(f"/v1/jobs/{job.id}/{path}", params=params), 410)
            assert d["code"] == "artifact_missing", (path, params, d)
            assert "cloud (cloud.ply) is no longer in the artifact store" in d["message"], d
    # The report is built from the job's files on first request: it names the one that has gone
    # (it was a 507 "the service cannot store files", though nothing was being stored).
    for path in ("report", "artifacts/report"):
        d = detail(client.get(f"/v1/jobs/{job.id}/{path}"), 410)
        assert d["code"] == "artifact_missing" and "report cannot be built" in d["message"], d
        assert "'cloud' (cloud.ply)" in d["message"], d
    page = client.get(f"/jobs/{job.id}")
    assert page.status_code == 410 and "Report unavailable" in page.text and "cloud.ply" in page.text


def test_a_report_whose_input_has_gone_names_the_input_and_a_built_one_is_still_served(client: TestClient) -> None:
    job = succeeded_linescan_job(client)
    service = service_of(client)
    service.artifacts.path(job.id, "input-tracks.json").unlink()
    d = detail(client.get(f"/v1/jobs/{job.id}/report"), 410)
    assert "its input 'tracks' (input-tracks.json)" in d["message"], d
    service.artifacts.save_bytes(job.id, "report.html", b"<!DOCTYPE html><p>built before</p>")
    r = client.get(f"/v1/jobs/{job.id}/report")
    assert r.status_code == 200 and "built before" in r.text


def test_a_download_is_saved_as_the_name_the_listing_gives(client: TestClient) -> None:
    job = succeeded_linescan_job(client)
    service_of(client).artifacts.save_bytes(job.id, "report.html", b"<!DOCTYPE html>")
    listed = {a["name"]: a["filename"] for a in client.get(f"/v1/jobs/{job.id}/artifacts").json()}
    assert listed == {"cloud": "cloud.ply", "report": "report.html"}
    for path in ("cloud", "artifacts/cloud"):
        assert saved_as(client.get(f"/v1/jobs/{job.id}/{path}")) == listed["cloud"], path
        assert saved_as(client.get(f"/v1/jobs/{job.id}/{path}", params={"format": "npz"})) == "cloud.npz", path
    for path in ("report", "artifacts/report"):
        r = client.get(f"/v1/jobs/{job.id}/{path}")
        # Shown in the browser, saved under the listed name.
        assert r.headers["content-disposition"].startswith("inline") and saved_as(r) == listed["report"], path


def test_cancelling_a_running_job_answers_that_the_cancellation_was_requested(client: TestClient) -> None:
    store = service_of(client).store
    running = store.create(kind="bearings", options={}, input={}, owner=None)
    assert store.claim(running.id) is not None
    assert client.get(f"/v1/jobs/{running.id}").json()["cancel_requested"] is False
    r = client.delete(f"/v1/jobs/{running.id}")
    assert r.status_code == 200, r.text
    # It stops at its next check, within seconds; until then it is still running, and says so.
    assert r.json()["status"] == "running" and r.json()["cancel_requested"] is True
    assert client.get(f"/v1/jobs/{running.id}").json()["cancel_requested"] is True
    queued = store.create(kind="bearings", options={}, input={}, owner=None)
    r = client.delete(f"/v1/jobs/{queued.id}")
    assert r.json()["status"] == "cancelled" and r.json()["cancel_requested"] is True
    schema = client.get("/openapi.json").json()["components"]["schemas"]["JobPublic"]
    assert "cancel_requested" in schema["required"]


def test_not_ready_is_a_503_with_retry_after(client: TestClient) -> None:
    r = client.get("/readyz")  # no worker process runs here
    assert r.status_code == 503 and r.json()["checks"]["workers"] == "none"
    assert r.headers["retry-after"] == "5"


def test_a_page_opened_with_a_bad_key_says_the_key_is_invalid(tmp_path: Path) -> None:
    settings = Settings(data_dir=tmp_path / "data", api_keys="good-key")
    with TestClient(create_app(settings)) as c:
        r = c.get("/")
        assert r.status_code == 401 and "API key required" in r.text
        r = c.get("/", params={"api_key": "bad-key"})
        assert r.status_code == 401 and "Invalid API key" in r.text and "API key required" not in r.text
        # A key given in the URL is the one meant: a stale cookie neither hides nor overrides it.
        c.cookies.set("tumblescan_key", "stale-key")
        r = c.get("/", params={"api_key": "good-key"})
        assert r.status_code == 200, r.text
        c.cookies.set("tumblescan_key", "good-key")
        assert c.get("/", params={"api_key": "bad-key"}).status_code == 401
