"""Downloads never leave a half-written ``.part`` file beside the target when they fail."""

from __future__ import annotations

import asyncio
from pathlib import Path

import httpx
import pytest

from tumblescan_client import AsyncClient, Client


def _serve_bytes(request: httpx.Request) -> httpx.Response:
    return httpx.Response(200, content=b"<!DOCTYPE html>report")


def test_a_download_into_a_directory_fails_and_leaves_no_part_file(tmp_path: Path) -> None:
    target = tmp_path / "report.html"
    target.mkdir()  # where the file should go is a directory
    with Client("http://svc", transport=httpx.MockTransport(_serve_bytes)) as client, pytest.raises(OSError):
        client.jobs.download_report("abc", target)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report.html"]
    with Client("http://svc", transport=httpx.MockTransport(_serve_bytes)) as client:
        assert client.jobs.download_report("abc", tmp_path / "ok.html").read_bytes() == b"<!DOCTYPE html>report"


def test_the_async_download_cleans_up_the_same_way(tmp_path: Path) -> None:
    target = tmp_path / "report.html"
    target.mkdir()

    async def go() -> None:
        async with AsyncClient("http://svc", transport=httpx.MockTransport(_serve_bytes)) as client:
            await client.jobs.download_report("abc", target)

    with pytest.raises(OSError):
        asyncio.run(go())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report.html"]


@pytest.mark.parametrize("url", ["notaurl", "127.0.0.1:8000", "ftp://host"])
def test_a_service_url_without_http_is_refused_at_once(url: str) -> None:
    # httpx failed every request with a transport error, which the client retried with backoff.
    with pytest.raises(ValueError, match="must start with http:// or https://"):
        Client(url)
    with pytest.raises(ValueError, match="must start with http:// or https://"):
        AsyncClient(url)
