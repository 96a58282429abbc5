"""The SDK (sync and async) against a live service, and its retries against a flaky server."""

from __future__ import annotations

import asyncio
import threading
import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest
import uvicorn
from fastapi import FastAPI
from fastapi.responses import JSONResponse

from tumblescan import TimedCloud, read_ply, tracks_to_json, write_ply
from tumblescan.linescan.tracks_io import write_tracks
from tumblescan_client import (
    APIConnectionError,
    AsyncClient,
    Client,
    JobFailedError,
    NotFoundError,
    RateLimitError,
    RetryPolicy,
    ServiceUnavailableError,
    UnprocessableEntityError,
)

from ..conftest import tracks_for
from ..live import free_port, serve

SLOW = {"strategy": "swarm", "swarm": {"particles": 3000, "iterations": 5000}}


@pytest.fixture(scope="module")
def url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    with serve(tmp_path_factory.mktemp("sdk") / "data") as u:
        yield u


def test_sync_client_full_cycle(url: str, tmp_path: Path) -> None:
    motion, tracks = tracks_for(40)
    write_tracks(tmp_path / "t.json", tracks)
    rng = np.random.default_rng(1)
    write_ply(tmp_path / "c.ply", TimedCloud(rng.normal(size=(300, 3)) + [0, 0, 50], rng.uniform(0, 14, 300)))
    with Client(url) as client:
        job = client.jobs.upload(tmp_path / "t.json", cloud=tmp_path / "c.ply", options={"seed": 2})
        result = client.jobs.result(job.id, timeout=120)
        assert result.model == "spin-precession" and result.validation.passed
        assert abs(result.spin.rate_deg_s - np.degrees(motion.spin_rate_rad_s)) < 5 * result.uncertainty.spin_rate_deg_s
        path = client.jobs.download_cloud(job.id, tmp_path / "r.ply")
        assert len(read_ply(path)) == 300
        created = client.jobs.create(tracks=tracks_to_json(tracks))
        assert client.jobs.get(created.id).kind == "linescan-motion"
        client.jobs.wait(created.id, timeout=120)
        ids = [j.id for j in client.jobs.list(status="succeeded", page_size=1)]
        assert {job.id, created.id} <= set(ids) and len(ids) == len(set(ids))


def test_sync_client_errors_are_typed(url: str) -> None:
    with Client(url) as client:
        with pytest.raises(NotFoundError) as nf:
            client.jobs.get("0" * 32)
        assert nf.value.status_code == 404 and nf.value.code == "not_found"
        with pytest.raises(UnprocessableEntityError) as bad:
            client.jobs.create(tracks={"observations": []}, options={"colour": 1})
        assert bad.value.code == "invalid_options" and "options.colour" in bad.value.message
        job = client.jobs.create(tracks=tracks_to_json(tracks_for(41)[1]), options=SLOW)
        cancelled = client.jobs.cancel(job.id)
        assert cancelled.status in ("cancelled", "running")
        with pytest.raises(JobFailedError, match="cancelled"):
            client.jobs.result(job.id, timeout=30)


def test_async_client_full_cycle(url: str, tmp_path: Path) -> None:
    _, tracks = tracks_for(42)
    write_tracks(tmp_path / "t.csv", tracks)

    async def main() -> None:
        async with AsyncClient(url) as client:
            jobs = await asyncio.gather(
                *(client.jobs.upload(tmp_path / "t.csv", options={"seed": s}) for s in range(4))
            )
            results = await asyncio.gather(*(client.jobs.result(j.id, timeout=120) for j in jobs))
            assert all(r.fit.observations == len(tracks) for r in results)
            seen = [j.id async for j in client.jobs.list(page_size=2)]
            assert {j.id for j in jobs} <= set(seen)
            with pytest.raises(NotFoundError):
                await client.jobs.cancel("f" * 32)

    asyncio.run(main())


class Flaky:
    """A real HTTP server that fails the first ``n`` calls of each path with a given status."""

    def __init__(self) -> None:
        self.hits: Counter[str] = Counter()
        app = FastAPI()

        @app.get("/v1/jobs/{job_id}")
        def job(job_id: str) -> JSONResponse:
            kind, _, n = job_id.partition("-")
            self.hits[job_id] += 1
            if self.hits[job_id] <= int(n or 0) or kind == "always503":
                status = {"r503": 503, "r429": 429, "always503": 503}.get(kind, 500)
                return JSONResponse(
                    {"detail": {"code": "busy", "message": "try later"}},
                    status_code=status,
                    headers={"Retry-After": "0"},
                )
            return JSONResponse(
                {
                    "id": job_id, "kind": "linescan-motion", "status": "queued", "progress": 0.0, "stage": "queued",
                    "created_at": "2026-01-01T00:00:00Z", "started_at": None, "finished_at": None,
                    "error": None, "result": None, "artifacts": {"cloud": None},
                }
            )  # fmt: skip

        self.port = free_port()
        self.server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=self.port, log_level="warning"))
        self.thread = threading.Thread(target=self.server.run, daemon=True)

    def __enter__(self) -> str:
        self.thread.start()
        deadline = time.monotonic() + 10
        while not self.server.started:
            assert time.monotonic() < deadline
            time.sleep(0.02)
        return f"http://127.0.0.1:{self.port}"

    def __exit__(self, *exc: object) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=10)


def test_retries_honour_503_and_429_then_succeed() -> None:
    flaky = Flaky()
    with flaky as url, Client(url, max_retries=3) as client:
        assert client.jobs.get("r503-2").id == "r503-2"
        assert client.jobs.get("r429-3").id == "r429-3"
        assert flaky.hits["r503-2"] == 3 and flaky.hits["r429-3"] == 4
        with pytest.raises(ServiceUnavailableError) as exc:
            client.jobs.get("always503")
        assert flaky.hits["always503"] == 4 and exc.value.code == "busy"
        with pytest.raises(RateLimitError):
            Client(url, max_retries=1).jobs.get("r429-5")


def test_async_retries_too() -> None:
    flaky = Flaky()

    async def main(url: str) -> None:
        async with AsyncClient(url, max_retries=2) as client:
            assert (await client.jobs.get("r503-2")).id == "r503-2"
            with pytest.raises(ServiceUnavailableError):
                await client.jobs.get("always503")

    with flaky as url:
        asyncio.run(main(url))
    assert flaky.hits["r503-2"] == 3 and flaky.hits["always503"] == 3


def test_backoff_is_capped_exponential_with_jitter_and_obeys_retry_after() -> None:
    policy = RetryPolicy(max_retries=5, initial_delay_s=0.5, max_delay_s=4.0)
    for attempt, cap in [(0, 0.5), (1, 1.0), (2, 2.0), (3, 4.0), (6, 4.0)]:
        d = policy.delay(attempt, None)
        assert 0.75 * cap <= d <= cap
    resp = httpx.Response(503, headers={"Retry-After": "3"})
    assert policy.delay(0, resp) == 3.0
    assert policy.delay(0, httpx.Response(429, headers={"retry-after-ms": "250"})) == 0.25
    # A Retry-After beyond max_retry_after_s is not retried at all: the error is raised at once.
    assert not policy.should_retry(0, httpx.Response(503, headers={"Retry-After": "3600"}))
    assert not policy.should_retry(5, resp) and policy.should_retry(0, resp)
    assert not policy.should_retry(0, httpx.Response(404))


def test_connection_errors_are_raised_after_retries() -> None:
    policy = RetryPolicy(max_retries=1, initial_delay_s=0.01)
    with (
        Client(f"http://127.0.0.1:{free_port()}", retry=policy) as client,
        pytest.raises(APIConnectionError, match="cannot reach"),
    ):
        client.jobs.get("x")
