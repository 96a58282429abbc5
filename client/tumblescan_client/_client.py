"""``Client`` and ``AsyncClient``: twins over httpx with the same resources and behaviour."""

from __future__ import annotations

import asyncio
import json
import os
import time
from collections.abc import AsyncIterator, Callable, Iterator
from pathlib import Path
from typing import Any

import httpx

from ._retry import RetryPolicy
from .errors import APIConnectionError, APITimeoutError, JobFailedError, WaitTimeoutError, error_for
from .models import Job, JobPage, MotionResult

DEFAULT_URL = "http://127.0.0.1:8000"
DEFAULT_TIMEOUT = httpx.Timeout(30.0, connect=5.0)
Progress = Callable[[Job], None]


def _configure(
    base_url: str | None, api_key: str | None, max_retries: int, retry: RetryPolicy | None
) -> tuple[str, dict[str, str], RetryPolicy]:
    """Base URL, headers and retry policy, from the arguments or the environment."""
    url = base_url or os.environ.get("TUMBLESCAN_URL") or DEFAULT_URL
    key = api_key or os.environ.get("TUMBLESCAN_API_KEY")
    headers = {"User-Agent": "tumblescan-client/0.1"}
    if key:
        headers["Authorization"] = f"Bearer {key}"
    return url, headers, retry or RetryPolicy(max_retries=max_retries)


def _transport_error(exc: httpx.TransportError) -> Exception:
    if isinstance(exc, httpx.TimeoutException):
        return APITimeoutError(f"request timed out: {exc}")
    return APIConnectionError(f"cannot reach the service: {exc}")


def _retry_delay(policy: RetryPolicy, attempt: int, resp: httpx.Response | None, error: Exception | None) -> float:
    """Seconds to wait before the next try; raises the final error when none is left."""
    if not policy.should_retry(attempt, resp):
        if resp is not None:
            raise error_for(resp)
        assert error is not None
        raise error
    return policy.delay(attempt, resp)


def _upload_parts(
    path: str | os.PathLike[str],
    extra: dict[str, str | os.PathLike[str] | None],
    options: dict[str, Any] | None,
    kind: str,
) -> tuple[dict[str, Any], dict[str, str]]:
    """Multipart parts: ``file`` plus any of ``cloud``/``truth``; the caller closes the files."""
    named = {"file": path} | {k: v for k, v in extra.items() if v is not None}
    files = {k: (Path(v).name, open(v, "rb"), "application/octet-stream") for k, v in named.items()}  # noqa: SIM115
    return files, {"options": json.dumps(options or {}), "kind": kind}


def _close(files: dict[str, Any]) -> None:
    for _, fh, _ in files.values():
        fh.close()


def _next_poll(delay: float) -> float:
    return min(delay * 1.5, 2.0)


LONG_POLL_S = 10.0


def _hold(deadline: float | None) -> float:
    """How long the service may hold one long-poll request."""
    if deadline is None:
        return LONG_POLL_S
    return round(max(0.0, min(LONG_POLL_S, deadline - time.monotonic())), 3)


class Jobs:
    """``client.jobs``: create, upload, get, wait, result, download_cloud, cancel, list."""

    def __init__(self, client: Client) -> None:
        self._c = client

    def create(
        self,
        *,
        tracks: dict[str, Any],
        options: dict[str, Any] | None = None,
        kind: str = "linescan-motion",
        timeout: float | None = None,
    ) -> Job:
        body = {"kind": kind, "input": {"tracks": tracks}, "options": options or {}}
        return Job.model_validate(self._c._request("POST", "/v1/jobs", json=body, timeout=timeout).json())

    def upload(
        self,
        path: str | os.PathLike[str],
        *,
        cloud: str | os.PathLike[str] | None = None,
        truth: str | os.PathLike[str] | None = None,
        options: dict[str, Any] | None = None,
        kind: str = "linescan-motion",
        timeout: float | None = None,
    ) -> Job:
        def send() -> httpx.Response:
            files, data = _upload_parts(path, {"cloud": cloud, "truth": truth}, options, kind)
            try:
                return self._c._http.request(
                    "POST", "/v1/jobs/upload", files=files, data=data, timeout=timeout or httpx.USE_CLIENT_DEFAULT
                )
            finally:
                _close(files)

        return Job.model_validate(self._c._send(send).json())

    def get(self, job_id: str, *, timeout: float | None = None) -> Job:
        return Job.model_validate(self._c._request("GET", f"/v1/jobs/{job_id}", timeout=timeout).json())

    def wait(self, job_id: str, *, timeout: float | None = 600.0, on_progress: Progress | None = None) -> Job:
        """Wait until the job is finished, long-polling the service (each request returns as
        soon as the job changes), with backoff between requests from 10 ms to 2 s."""
        deadline = None if timeout is None else time.monotonic() + timeout
        delay = 0.01
        while True:
            job = self._get_waiting(job_id, _hold(deadline))
            if on_progress:
                on_progress(job)
            if job.done:
                return job
            if deadline is not None and time.monotonic() >= deadline:
                raise WaitTimeoutError(f"job {job_id} still {job.status} after {timeout} s")
            time.sleep(delay)
            delay = _next_poll(delay)

    def _get_waiting(self, job_id: str, hold_s: float) -> Job:
        resp = self._c._request("GET", f"/v1/jobs/{job_id}", params={"wait": hold_s}, timeout=hold_s + 30)
        return Job.model_validate(resp.json())

    def result(self, job_id: str, *, timeout: float | None = 600.0) -> MotionResult:
        """Wait for the job and return its typed motion result (JobFailedError otherwise)."""
        job = self.wait(job_id, timeout=timeout)
        if job.status != "succeeded" or job.result is None:
            raise JobFailedError(job)
        return MotionResult.model_validate(job.result)

    def download_cloud(
        self, job_id: str, path: str | os.PathLike[str], *, format: str = "ply", timeout: float | None = None
    ) -> Path:
        """Stream the rectified cloud (PLY, or NPZ with ``format="npz"``) to ``path``."""
        return self._download(f"/v1/jobs/{job_id}/cloud", {"format": format}, path, timeout)

    def download_report(self, job_id: str, path: str | os.PathLike[str], *, timeout: float | None = None) -> Path:
        """Save the job's self-contained HTML report to ``path``."""
        return self._download(f"/v1/jobs/{job_id}/report", {}, path, timeout)

    def _download(self, url: str, params: dict[str, Any], path: str | os.PathLike[str], timeout: float | None) -> Path:
        out = Path(path)
        tmp = out.with_name(out.name + ".part")

        def send() -> httpx.Response:
            req = self._c._http.build_request("GET", url, params=params, timeout=timeout or httpx.USE_CLIENT_DEFAULT)
            resp = self._c._http.send(req, stream=True)
            if resp.status_code != 200:
                resp.read()
                return resp
            with open(tmp, "wb") as fh:
                for chunk in resp.iter_bytes(1 << 20):
                    fh.write(chunk)
            resp.close()
            return resp

        self._c._send(send)
        tmp.replace(out)
        return out

    def cancel(self, job_id: str, *, timeout: float | None = None) -> Job:
        return Job.model_validate(self._c._request("DELETE", f"/v1/jobs/{job_id}", timeout=timeout).json())

    def list(self, *, status: str | None = None, page_size: int = 50) -> Iterator[Job]:
        """Every job (newest first), fetching pages as the iteration goes."""
        cursor = None
        while True:
            params: dict[str, Any] = {"limit": page_size}
            if status:
                params["status"] = status
            if cursor:
                params["cursor"] = cursor
            page = JobPage.model_validate(self._c._request("GET", "/v1/jobs", params=params).json())
            yield from page.items
            if not page.next_cursor:
                return
            cursor = page.next_cursor


class Client:
    """Synchronous client. ``api_key`` defaults to ``TUMBLESCAN_API_KEY``, ``base_url`` to
    ``TUMBLESCAN_URL`` or http://127.0.0.1:8000."""

    def __init__(
        self,
        base_url: str | None = None,
        *,
        api_key: str | None = None,
        timeout: float | httpx.Timeout = DEFAULT_TIMEOUT,
        max_retries: int = 3,
        retry: RetryPolicy | None = None,
        transport: httpx.BaseTransport | None = None,
    ) -> None:
        url, headers, self.retry = _configure(base_url, api_key, max_retries, retry)
        self._http = httpx.Client(base_url=url, headers=headers, timeout=timeout, transport=transport)
        self.jobs = Jobs(self)

    def _request(self, method: str, path: str, *, timeout: float | None = None, **kw: Any) -> httpx.Response:
        return self._send(lambda: self._http.request(method, path, timeout=timeout or httpx.USE_CLIENT_DEFAULT, **kw))

    def _send(self, send: Callable[[], httpx.Response]) -> httpx.Response:
        attempt = 0
        while True:
            try:
                resp, error = send(), None
            except httpx.TransportError as exc:
                resp, error = None, _transport_error(exc)
            if resp is not None and resp.status_code < 400:
                return resp
            time.sleep(_retry_delay(self.retry, attempt, resp, error))
            attempt += 1

    def close(self) -> None:
        self._http.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class AsyncJobs:
    """``async_client.jobs``: the same operations as :class:`Jobs`, awaitable."""

    def __init__(self, client: AsyncClient) -> None:
        self._c = client

    async def create(
        self,
        *,
        tracks: dict[str, Any],
        options: dict[str, Any] | None = None,
        kind: str = "linescan-motion",
        timeout: float | None = None,
    ) -> Job:
        body = {"kind": kind, "input": {"tracks": tracks}, "options": options or {}}
        return Job.model_validate((await self._c._request("POST", "/v1/jobs", json=body, timeout=timeout)).json())

    async def upload(
        self,
        path: str | os.PathLike[str],
        *,
        cloud: str | os.PathLike[str] | None = None,
        truth: str | os.PathLike[str] | None = None,
        options: dict[str, Any] | None = None,
        kind: str = "linescan-motion",
        timeout: float | None = None,
    ) -> Job:
        async def send() -> httpx.Response:
            files, data = _upload_parts(path, {"cloud": cloud, "truth": truth}, options, kind)
            try:
                return await self._c._http.request(
                    "POST", "/v1/jobs/upload", files=files, data=data, timeout=timeout or httpx.USE_CLIENT_DEFAULT
                )
            finally:
                _close(files)

        return Job.model_validate((await self._c._send(send)).json())

    async def get(self, job_id: str, *, timeout: float | None = None) -> Job:
        return Job.model_validate((await self._c._request("GET", f"/v1/jobs/{job_id}", timeout=timeout)).json())

    async def wait(self, job_id: str, *, timeout: float | None = 600.0, on_progress: Progress | None = None) -> Job:
        deadline = None if timeout is None else time.monotonic() + timeout
        delay = 0.01
        while True:
            hold = _hold(deadline)
            resp = await self._c._request("GET", f"/v1/jobs/{job_id}", params={"wait": hold}, timeout=hold + 30)
            job = Job.model_validate(resp.json())
            if on_progress:
                on_progress(job)
            if job.done:
                return job
            if deadline is not None and time.monotonic() >= deadline:
                raise WaitTimeoutError(f"job {job_id} still {job.status} after {timeout} s")
            await asyncio.sleep(delay)
            delay = _next_poll(delay)

    async def result(self, job_id: str, *, timeout: float | None = 600.0) -> MotionResult:
        job = await self.wait(job_id, timeout=timeout)
        if job.status != "succeeded" or job.result is None:
            raise JobFailedError(job)
        return MotionResult.model_validate(job.result)

    async def download_cloud(
        self, job_id: str, path: str | os.PathLike[str], *, format: str = "ply", timeout: float | None = None
    ) -> Path:
        return await self._download(f"/v1/jobs/{job_id}/cloud", {"format": format}, path, timeout)

    async def download_report(self, job_id: str, path: str | os.PathLike[str], *, timeout: float | None = None) -> Path:
        return await self._download(f"/v1/jobs/{job_id}/report", {}, path, timeout)

    async def _download(
        self, url: str, params: dict[str, Any], path: str | os.PathLike[str], timeout: float | None
    ) -> Path:
        out = Path(path)
        tmp = out.with_name(out.name + ".part")

        async def send() -> httpx.Response:
            req = self._c._http.build_request("GET", url, params=params, timeout=timeout or httpx.USE_CLIENT_DEFAULT)
            resp = await self._c._http.send(req, stream=True)
            if resp.status_code != 200:
                await resp.aread()
                return resp
            with open(tmp, "wb") as fh:
                async for chunk in resp.aiter_bytes(1 << 20):
                    fh.write(chunk)
            await resp.aclose()
            return resp

        await self._c._send(send)
        tmp.replace(out)
        return out

    async def cancel(self, job_id: str, *, timeout: float | None = None) -> Job:
        return Job.model_validate((await self._c._request("DELETE", f"/v1/jobs/{job_id}", timeout=timeout)).json())

    async def list(self, *, status: str | None = None, page_size: int = 50) -> AsyncIterator[Job]:
        cursor = None
        while True:
            params: dict[str, Any] = {"limit": page_size}
            if status:
                params["status"] = status
            if cursor:
                params["cursor"] = cursor
            page = JobPage.model_validate((await self._c._request("GET", "/v1/jobs", params=params)).json())
            for job in page.items:
                yield job
            if not page.next_cursor:
                return
            cursor = page.next_cursor


class AsyncClient:
    """Asynchronous twin of :class:`Client`."""

    def __init__(
        self,
        base_url: str | None = None,
        *,
        api_key: str | None = None,
        timeout: float | httpx.Timeout = DEFAULT_TIMEOUT,
        max_retries: int = 3,
        retry: RetryPolicy | None = None,
        transport: httpx.AsyncBaseTransport | None = None,
    ) -> None:
        url, headers, self.retry = _configure(base_url, api_key, max_retries, retry)
        self._http = httpx.AsyncClient(base_url=url, headers=headers, timeout=timeout, transport=transport)
        self.jobs = AsyncJobs(self)

    async def _request(self, method: str, path: str, *, timeout: float | None = None, **kw: Any) -> httpx.Response:
        async def send() -> httpx.Response:
            return await self._http.request(method, path, timeout=timeout or httpx.USE_CLIENT_DEFAULT, **kw)

        return await self._send(send)

    async def _send(self, send: Callable[[], Any]) -> httpx.Response:
        attempt = 0
        while True:
            try:
                resp, error = await send(), None
            except httpx.TransportError as exc:
                resp, error = None, _transport_error(exc)
            if resp is not None and resp.status_code < 400:
                return resp
            await asyncio.sleep(_retry_delay(self.retry, attempt, resp, error))
            attempt += 1

    async def close(self) -> None:
        await self._http.aclose()

    async def __aenter__(self) -> AsyncClient:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()
