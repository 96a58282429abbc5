"""The HTTP API against a real ``tumblescan serve`` (uvicorn, SQLite store and queue, 2 workers)."""

from __future__ import annotations

import io
import json
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from tumblescan import (
    EstimateOptions,
    TimedCloud,
    estimate_motion,
    read_ply,
    rectify,
    tracks_from_json,
    tracks_to_json,
    write_ply,
)
from tumblescan.linescan.tracks_io import write_tracks
from tumblescan.linescan.truth import errors_against

from ..conftest import tracks_for
from ..live import serve, wait_job

FINAL = ("succeeded", "failed", "cancelled")


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("svc") / "data"


@pytest.fixture(scope="module")
def url(data_dir: Path) -> Iterator[str]:
    with serve(data_dir) as u:
        yield u


@pytest.fixture(scope="module")
def http(url: str) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=url, timeout=30) as c:
        yield c


def wait(http: httpx.Client, job_id: str, timeout_s: float = 120) -> dict[str, Any]:
    return wait_job(http, job_id, timeout_s=timeout_s)


def tracks_doc(seed: int) -> dict[str, Any]:
    return tracks_to_json(tracks_for(seed)[1])


def test_json_job_runs_and_returns_the_core_result(http: httpx.Client, url: str) -> None:
    motion, tracks = tracks_for(21)
    r = http.post(
        "/v1/jobs",
        json={"kind": "linescan-motion", "input": {"tracks": tracks_to_json(tracks)}, "options": {"seed": 3}},
    )
    assert r.status_code == 202
    job = r.json()
    assert r.headers["location"] == f"{url}/v1/jobs/{job['id']}"
    assert job["status"] in ("queued", "running") and job["result"] is None
    done = wait(http, job["id"])
    assert done["status"] == "succeeded" and done["progress"] == 1.0 and done["error"] is None
    assert done["started_at"] and done["finished_at"] and "cloud" not in done["artifacts"]
    assert done["artifacts"]["report"] == f"{url}/v1/jobs/{job['id']}/report"
    # The service returns exactly what the library computes with the same options.
    direct = estimate_motion(tracks, EstimateOptions(seed=3)).model_dump(mode="json")
    got = done["result"]
    for key in ("model", "reference_time_s", "spin", "precession", "uncertainty", "fit", "validation", "warnings"):
        assert got[key] == direct[key], key
    from tumblescan import MotionResult

    err = errors_against(MotionResult.model_validate(got), motion)
    assert abs(err["spin_rate_deg_s"]) < 5 * got["uncertainty"]["spin_rate_deg_s"]


def test_upload_with_cloud_returns_the_rectified_cloud(http: httpx.Client, tmp_path: Path) -> None:
    _, tracks = tracks_for(22)
    write_tracks(tmp_path / "t.csv", tracks)
    rng = np.random.default_rng(0)
    cloud = TimedCloud(
        rng.normal(size=(5000, 3)) + [0, 0, 50],
        np.sort(rng.uniform(0, 14, 5000)),
        {"intensity": rng.random(5000).astype(np.float32)},
    )
    write_ply(tmp_path / "c.ply", cloud)
    with open(tmp_path / "t.csv", "rb") as t, open(tmp_path / "c.ply", "rb") as c:
        r = http.post(
            "/v1/jobs/upload",
            files={"file": ("t.csv", t), "cloud": ("c.ply", c)},
            data={"options": json.dumps({"seed": 1})},
        )
    assert r.status_code == 202, r.text
    done = wait(http, r.json()["id"])
    assert done["status"] == "succeeded", done
    assert done["artifacts"]["cloud"].endswith(f"/v1/jobs/{done['id']}/cloud")
    ply = http.get(done["artifacts"]["cloud"])
    assert ply.status_code == 200
    (tmp_path / "out.ply").write_bytes(ply.content)
    got = read_ply(tmp_path / "out.ply")
    from tumblescan import MotionResult

    result = MotionResult.model_validate(done["result"])
    expected = rectify(cloud.xyz_m, cloud.t_s, result.motion(), to_time_s=result.reference_time_s)
    assert np.allclose(got.xyz_m, expected, atol=1e-9)
    assert np.array_equal(got.fields["intensity"], cloud.fields["intensity"])
    npz = np.load(io.BytesIO(http.get(f"/v1/jobs/{done['id']}/cloud", params={"format": "npz"}).content))
    assert np.allclose(npz["xyz_m"], expected, atol=1e-9) and np.array_equal(npz["t_s"], cloud.t_s)


@pytest.mark.parametrize(
    ("body", "code", "fragment"),
    [
        (
            {"kind": "linescan-motion", "input": {"tracks": {}}, "options": {"colour": 1}},
            "invalid_options",
            "options.colour: unknown option",
        ),
        (
            {"kind": "linescan-motion", "input": {"tracks": {}}, "options": {"strategy": "magic"}},
            "invalid_options",
            "options.strategy",
        ),
        ({"kind": "nope", "input": {}}, "unknown_kind", "unknown job kind 'nope'"),
        ({"kind": "linescan-motion", "input": {"tracks": {"observations": []}}}, "malformed_input", "non-empty list"),
        ({"kind": "linescan-motion", "input": {"frames": 1}}, "malformed_input", "input must be"),
        ({"kind": "linescan-motion"}, "invalid_request", "body.input: Field required"),
        ({"kind": "linescan-motion", "input": {}, "extra": 1}, "invalid_request", "body.extra"),
    ],
)
def test_bad_json_submissions_are_422_naming_the_problem(
    http: httpx.Client, body: dict[str, Any], code: str, fragment: str
) -> None:
    r = http.post("/v1/jobs", json=body)
    assert r.status_code == 422, r.text
    detail = r.json()["detail"]
    assert detail["code"] == code and fragment in detail["message"]


def test_bad_tracks_are_422_with_the_field(http: httpx.Client) -> None:
    doc = tracks_doc(23)
    doc["observations"][5]["xyz"] = [1.0, 2.0]
    r = http.post("/v1/jobs", json={"input": {"tracks": doc}})
    assert r.status_code == 422
    assert r.json()["detail"]["field"] == "observations[5].xyz"
    r = http.post(
        "/v1/jobs",
        content=b'{"input": {"tracks": {"observations": [{"track": "a", "t": NaN, "xyz": [1,2,3]}]}}}',
        headers={"content-type": "application/json"},
    )
    assert r.status_code == 422 and r.json()["detail"]["code"] in ("non_finite_value", "invalid_request")


def test_bad_uploads_are_422(http: httpx.Client, tmp_path: Path) -> None:
    ply = tmp_path / "c.ply"
    write_ply(ply, TimedCloud(np.zeros((3, 3)), np.arange(3.0)))
    r = http.post("/v1/jobs/upload", files={"file": ("c.ply", ply.read_bytes())})
    # Times evenly spread, no frame indices, no period: the frames cannot be told apart.
    assert r.status_code == 422 and "cannot tell the frames apart" in r.json()["detail"]["message"]
    assert r.json()["detail"]["field"] == "frame"
    r = http.post("/v1/jobs/upload", files={"file": ("t.json", b'{"observations": []}')}, data={"options": "{nope"})
    assert r.status_code == 422 and r.json()["detail"]["field"] == "options"
    r = http.post(
        "/v1/jobs/upload",
        files={"file": ("t.json", json.dumps(tracks_doc(24)).encode()), "cloud": ("c.ply", b"ply\nformat ascii 1.0\n")},
    )
    assert r.status_code == 422 and "end_header" in r.json()["detail"]["message"]
    r = http.post("/v1/jobs/upload", data={"options": "{}"})
    assert r.status_code == 422 and "file" in r.json()["detail"]["message"]


def test_missing_jobs_and_clouds_are_404(http: httpx.Client) -> None:
    r = http.get("/v1/jobs/0123456789abcdef0123456789abcdef")
    assert r.status_code == 404 and r.json()["detail"]["code"] == "not_found"
    assert http.delete("/v1/jobs/0123456789abcdef0123456789abcdef").status_code == 404
    job = http.post("/v1/jobs", json={"input": {"tracks": tracks_doc(25)}}).json()
    wait(http, job["id"])
    r = http.get(f"/v1/jobs/{job['id']}/cloud")
    assert r.status_code == 404 and "no cloud" in r.json()["detail"]["message"]


def test_a_running_job_is_cancelled_within_seconds_and_its_files_deleted(http: httpx.Client, data_dir: Path) -> None:
    # A deliberately huge swarm keeps the job running for minutes unless cancelled.
    slow = {"strategy": "swarm", "swarm": {"particles": 3000, "iterations": 5000}}
    job = http.post("/v1/jobs", json={"input": {"tracks": tracks_doc(26)}, "options": slow}).json()
    deadline = time.monotonic() + 60
    while http.get(f"/v1/jobs/{job['id']}").json()["status"] != "running":
        assert time.monotonic() < deadline
        time.sleep(0.05)
    # The job's files exist while it runs (checked before the cancel: once it is asked for, the
    # worker may notice and delete them before this test runs its next line, on a loaded machine).
    assert (data_dir / "artifacts" / job["id"]).is_dir()
    r = http.delete(f"/v1/jobs/{job['id']}")
    assert r.status_code == 200
    done = wait(http, job["id"], timeout_s=20)
    assert done["status"] == "cancelled" and done["result"] is None
    assert not (data_dir / "artifacts" / job["id"]).exists()


def test_a_queued_job_is_cancelled_at_once(http: httpx.Client) -> None:
    slow = {"strategy": "swarm", "swarm": {"particles": 3000, "iterations": 5000}}
    blockers = [
        http.post("/v1/jobs", json={"input": {"tracks": tracks_doc(27)}, "options": slow}).json() for _ in range(2)
    ]
    queued = http.post("/v1/jobs", json={"input": {"tracks": tracks_doc(28)}}).json()
    r = http.delete(f"/v1/jobs/{queued['id']}")
    assert r.json()["status"] == "cancelled"
    for b in blockers:
        http.delete(f"/v1/jobs/{b['id']}")
    for b in blockers:
        assert wait(http, b["id"], timeout_s=20)["status"] == "cancelled"
    # A cancelled job never runs afterwards.
    time.sleep(0.5)
    assert http.get(f"/v1/jobs/{queued['id']}").json()["status"] == "cancelled"


def test_list_filters_by_status_and_pages_with_a_cursor(http: httpx.Client) -> None:
    ids = {http.post("/v1/jobs", json={"input": {"tracks": tracks_doc(29)}}).json()["id"] for _ in range(5)}
    for job_id in ids:
        wait(http, job_id)
    seen: list[str] = []
    cursor = None
    while True:
        params: dict[str, Any] = {"limit": 2, "status": "succeeded"}
        if cursor:
            params["cursor"] = cursor
        page = http.get("/v1/jobs", params=params).json()
        assert len(page["items"]) <= 2
        assert all(j["status"] == "succeeded" for j in page["items"])
        seen += [j["id"] for j in page["items"]]
        cursor = page["next_cursor"]
        if not cursor:
            break
    assert ids <= set(seen) and len(seen) == len(set(seen))
    created = [http.get(f"/v1/jobs/{i}").json()["created_at"] for i in seen]
    assert created == sorted(created, reverse=True)
    assert http.get("/v1/jobs", params={"status": "exploded"}).status_code == 422
    assert http.get("/v1/jobs", params={"cursor": "garbage!"}).status_code == 422


def test_health_readiness_metrics_and_openapi(http: httpx.Client) -> None:
    assert http.get("/healthz").json() == {"status": "ok"}
    ready = http.get("/readyz")
    assert ready.status_code == 200 and ready.json()["checks"]["workers"] == "2 process(es)"
    metrics = http.get("/metrics").text
    assert 'tumblescan_jobs{status="succeeded"}' in metrics
    assert "tumblescan_job_duration_seconds_bucket" in metrics and "tumblescan_queue_depth" in metrics
    spec = http.get("/openapi.json").json()
    ops = {op["operationId"] for path in spec["paths"].values() for op in path.values()}
    assert {
        "create_job",
        "upload_job",
        "get_job",
        "list_jobs",
        "get_job_cloud",
        "cancel_job",
        "healthz",
        "readyz",
        "metrics",
    } <= ops


def test_tracks_round_trip_through_the_service_unchanged(http: httpx.Client) -> None:
    # What the service stores is the caller's tracks, validated the same way as the library.
    doc = tracks_doc(30)
    job = http.post("/v1/jobs", json={"input": {"tracks": doc}}).json()
    done = wait(http, job["id"])
    assert done["result"]["fit"]["observations"] == len(tracks_from_json(doc))
