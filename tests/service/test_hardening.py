"""Hardening: access control, limits and hostile input against a live service."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from tumblescan import TimedCloud, tracks_to_json, write_ply

from ..conftest import tracks_for
from ..live import free_port, serve, wait_job

USER, OTHER, ADMIN = "user-key", "other-key", "admin-key"
LIMITS = {
    "TUMBLESCAN_API_KEYS": f"{USER},{OTHER}",
    "TUMBLESCAN_ADMIN_KEYS": ADMIN,
    "TUMBLESCAN_MAX_UPLOAD_BYTES": "300000",
    "TUMBLESCAN_MAX_OBSERVATIONS": "400",
    "TUMBLESCAN_MAX_CLOUD_POINTS": "2000",
    "TUMBLESCAN_JOB_TIMEOUT_S": "8",  # ordinary jobs finish well inside it even on a loaded machine
}
SLOW = {"strategy": "swarm", "swarm": {"particles": 3000, "iterations": 5000}}


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("hard") / "data"


@pytest.fixture(scope="module")
def url(data_dir: Path) -> Iterator[str]:
    with serve(data_dir, workers=2, extra_env=LIMITS) as u:
        yield u


def client(url: str, key: str | None) -> httpx.Client:
    return httpx.Client(base_url=url, timeout=30, headers={"Authorization": f"Bearer {key}"} if key else {})


def wait(http: httpx.Client, job_id: str, timeout_s: float = 60) -> dict[str, Any]:
    return wait_job(http, job_id, timeout_s=timeout_s)


def tracks(seed: int = 100) -> dict[str, Any]:
    return tracks_to_json(tracks_for(seed)[1])


def test_serving_beyond_localhost_without_keys_is_refused() -> None:
    cmd = [sys.executable, "-m", "tumblescan", "serve", "--host", "0.0.0.0", "--port", str(free_port())]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and "refusing to serve on 0.0.0.0 without API keys" in proc.stderr


def test_admin_sees_and_cancels_every_job_users_only_their_own(url: str) -> None:
    with client(url, USER) as user, client(url, OTHER) as other, client(url, ADMIN) as admin:
        mine = user.post("/v1/jobs", json={"input": {"tracks": tracks()}}).json()["id"]
        slow = other.post("/v1/jobs", json={"input": {"tracks": tracks()}, "options": SLOW}).json()["id"]
        # Cancelled first: the slow job would otherwise meet the 8 s job timeout on a loaded machine.
        assert admin.delete(f"/v1/jobs/{slow}").status_code == 200
        assert user.get(f"/v1/jobs/{slow}").status_code == 404
        assert user.delete(f"/v1/jobs/{slow}").status_code == 404
        seen = {j["id"] for j in admin.get("/v1/jobs", params={"limit": 500}).json()["items"]}
        assert {mine, slow} <= seen
        assert wait(other, slow)["status"] == "cancelled"
        assert wait(user, mine)["status"] == "succeeded"


def test_oversized_bodies_are_413_before_being_read(url: str) -> None:
    with client(url, USER) as http:
        big = b"x" * 1_000_000
        r = http.post("/v1/jobs/upload", files={"file": ("t.json", big)})
        assert r.status_code == 413 and r.json()["detail"]["code"] == "upload_too_large"

        def chunks() -> Iterator[bytes]:
            # No Content-Length: the limit is enforced while the body streams in.
            for _ in range(100):
                yield b"y" * 65536

        r = http.post("/v1/jobs", content=chunks(), headers={"content-type": "application/json"})
        assert r.status_code == 413
        assert http.get("/healthz").status_code == 200


def test_size_limits_on_observations_and_points(url: str, tmp_path: Path) -> None:
    with client(url, USER) as http:
        doc = tracks()
        doc["observations"] = doc["observations"] * 1  # 100+ observations are fine
        assert http.post("/v1/jobs", json={"input": {"tracks": doc}}).status_code == 202
        many = tracks_to_json(tracks_for(101, frames=60)[1])
        r = http.post("/v1/jobs", json={"input": {"tracks": many}})
        assert r.status_code == 422 and r.json()["detail"]["code"] == "limit_exceeded"
        cloud = tmp_path / "c.ply"
        rng = np.random.default_rng(0)
        write_ply(cloud, TimedCloud(rng.normal(size=(5000, 3)), rng.uniform(0, 1, 5000)))
        r = http.post(
            "/v1/jobs/upload",
            files={"file": ("t.json", json.dumps(tracks()).encode()), "cloud": ("c.ply", cloud.read_bytes())},
        )
        assert r.status_code == 422 and "limit is 2000" in r.json()["detail"]["message"]


def test_an_npz_that_would_expand_past_the_limit_is_refused_unread(url: str, tmp_path: Path) -> None:
    # 800 kB of zeros compress to a few kB; the archive's declared sizes give it away.
    bomb = tmp_path / "bomb.npz"
    arrays = {
        "range_m": np.zeros((10, 100, 100)),
        "t_s": np.zeros((10, 100)),
        "azimuth_deg": np.zeros(100),
        "elevation_deg": np.zeros(100),
    }
    np.savez_compressed(bomb, **arrays)  # type: ignore[arg-type]
    assert bomb.stat().st_size < 20_000
    with client(url, USER) as http:
        r = http.post("/v1/jobs/upload", files={"file": ("frames.npz", bomb.read_bytes())})
    detail = r.json()["detail"]
    assert r.status_code == 422 and detail["code"] == "limit_exceeded" and "would expand to" in detail["message"]


def test_a_job_over_its_time_limit_fails_clearly_and_frees_its_worker(url: str) -> None:
    with client(url, USER) as http:
        slow = http.post("/v1/jobs", json={"input": {"tracks": tracks()}, "options": SLOW}).json()["id"]
        job = wait(http, slow, timeout_s=60)
        assert (
            job["status"] == "failed"
            and job["error"]["code"] == "timeout"
            and "limit of 8 s" in job["error"]["message"]
        )
        ok = [http.post("/v1/jobs", json={"input": {"tracks": tracks()}}).json()["id"] for _ in range(4)]
        assert all(wait(http, i)["status"] == "succeeded" for i in ok)


@pytest.mark.parametrize(
    ("content", "code"),
    [
        (b'{"input": {"tracks": {}}, "options": {"reference_time_s": NaN}}', "invalid_options"),
        (b'{"input": {"tracks": {}}, "options": {"reference_time_s": Infinity}}', "invalid_options"),
        (b'{"input": {"tracks": {}}, "options": {"seed": "seven"}}', "invalid_options"),
        (b'{"input": [1, 2]}', "invalid_request"),
        (b'{"input": ', "invalid_request"),
        (b"\xff\xfe\x00", "malformed_input"),
    ],
)
def test_hostile_json_is_422_never_500(url: str, content: bytes, code: str) -> None:
    with client(url, USER) as http:
        r = http.post("/v1/jobs", content=content, headers={"content-type": "application/json"})
        assert r.status_code == 422, r.text
        detail = r.json()["detail"]
        assert detail["code"] == code and detail["message"]


def test_corrupt_clouds_and_path_tricks_are_handled(url: str, data_dir: Path, tmp_path: Path) -> None:
    good = tmp_path / "g.ply"
    write_ply(good, TimedCloud(np.zeros((100, 3)), np.arange(100.0)))
    raw = good.read_bytes()
    t = json.dumps(tracks()).encode()
    with client(url, USER) as http:
        for bad, fragment in [
            (raw[: len(raw) // 2], "truncated"),
            (raw.replace(b"element vertex 100", b"element vertex 99999999"), "declares 99999999 vertices"),
            (
                b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty list uchar int x\nend_header\n",
                "unsupported",
            ),
        ]:
            r = http.post("/v1/jobs/upload", files={"file": ("t.json", t), "cloud": ("c.ply", bad)})
            assert r.status_code == 422 and fragment in r.json()["detail"]["message"], r.text
        # The uploader's file name is never used as a path.
        r = http.post("/v1/jobs/upload", files={"file": ("../../../../tmp/evil.json", t)})
        assert r.status_code == 202
        assert not Path("/tmp/evil.json").exists()
        # It is reduced to a base name inside the job's folder.
        job_dir = data_dir / "artifacts" / r.json()["id"]
        assert (job_dir / "uploads" / "file" / "evil.json").is_file()


def test_unwritable_artifacts_fail_clearly_and_the_service_stays_up(url: str, data_dir: Path) -> None:
    artifacts = data_dir / "artifacts"
    moved = data_dir / "artifacts-moved"
    artifacts.rename(moved)
    artifacts.write_text("not a directory")  # writes under it now fail, even for root
    try:
        with client(url, USER) as http:
            r = http.post("/v1/jobs", json={"input": {"tracks": tracks()}})
            assert r.status_code == 507 and r.json()["detail"]["code"] == "storage_unavailable"
            assert http.get("/healthz").status_code == 200
    finally:
        artifacts.unlink()
        moved.rename(artifacts)
    with client(url, USER) as http:
        job = http.post("/v1/jobs", json={"input": {"tracks": tracks()}}).json()["id"]
        assert wait(http, job)["status"] == "succeeded"
    shutil.rmtree(moved, ignore_errors=True)
