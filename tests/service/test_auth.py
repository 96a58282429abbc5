"""With API keys configured every /v1 route needs one, and a job belongs to the key that made it."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from tumblescan import tracks_to_json
from tumblescan_client import AuthenticationError, Client, NotFoundError

from ..conftest import tracks_for
from ..live import serve


@pytest.fixture(scope="module")
def url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    data: Path = tmp_path_factory.mktemp("auth") / "data"
    with serve(data, workers=1, extra_env={"TUMBLESCAN_API_KEYS": "key-one,key-two"}) as u:
        yield u


def test_requests_without_a_valid_key_are_401(url: str) -> None:
    for key in (None, "wrong"):
        with Client(url, api_key=key) as anon, pytest.raises(AuthenticationError):
            anon.jobs.get("0" * 32)
    import httpx

    assert httpx.get(f"{url}/healthz").status_code == 200  # liveness stays open for probes


def test_a_job_is_invisible_to_another_key(url: str) -> None:
    tracks = tracks_to_json(tracks_for(70)[1])
    with Client(url, api_key="key-one") as one, Client(url, api_key="key-two") as two:
        job = one.jobs.create(tracks=tracks)
        assert one.jobs.wait(job.id, timeout=120).status == "succeeded"
        with pytest.raises(NotFoundError):
            two.jobs.get(job.id)
        with pytest.raises(NotFoundError):
            two.jobs.cancel(job.id)
        assert job.id not in {j.id for j in two.jobs.list()}
        assert job.id in {j.id for j in one.jobs.list()}
