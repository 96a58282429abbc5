"""``client.jobs`` and ``async_client.jobs``: the job resource twins (create, upload, wait, download)."""

from __future__ import annotations

import asyncio
import json
import os
import time
from collections.abc import AsyncIterator, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import httpx

from ._requests import (
    DEFAULT_KIND,
    Files,
    PathLike,
    Progress,
    close_parts,
    create_body,
    long_poll_hold,
    next_poll,
    open_parts,
    typed_result,
    upload_request,
)
from .errors import WaitTimeoutError
from .models import Artifact, Job, JobPage

if TYPE_CHECKING:
    from ._client import AsyncClient, Client


class Jobs:
    """``client.jobs``: create, upload, get, wait, result, download_cloud, cancel, list."""

    def __init__(self, client: Client) -> None:
        self._c = client

    def create(
        self,
        kind: str = DEFAULT_KIND,
        input: dict[str, Any] | None = None,
        *,
        options: dict[str, Any] | None = None,
        tracks: dict[str, Any] | None = None,
        timeout: float | None = None,
    ) -> Job:
        """Queue a job from JSON input (``client.kinds.get(kind)`` tells which forms take JSON)."""
        body = create_body(kind, input, tracks, options)
        return Job.model_validate(self._c._request("POST", "/v1/jobs", json=body, timeout=timeout).json())

    def upload(
        self,
        kind: str | os.PathLike[str],
        files: Files | None = None,
        *,
        options: dict[str, Any] | None = None,
        cloud: PathLike | None = None,
        truth: PathLike | None = None,
        timeout: float | None = None,
        **legacy: Any,
    ) -> Job:
        """Queue a job from files: ``upload("panel-axis", files={"meta": "meta.json", "image": "img.png"})``;
        a part may take several files (a list). ``upload(path, cloud=..., truth=...)`` still works
        for linescan-motion."""
        kind_name, parts = upload_request(kind, files, {"cloud": cloud, "truth": truth}, legacy.pop("kind", None))
        if legacy:
            raise TypeError(f"unexpected argument(s): {', '.join(legacy)}")

        def send() -> httpx.Response:
            opened = open_parts(parts)
            data = {"options": json.dumps(options or {}), "kind": kind_name}
            try:
                return self._c._http.request(
                    "POST", "/v1/jobs/upload", files=opened, data=data, timeout=timeout or httpx.USE_CLIENT_DEFAULT
                )
            finally:
                close_parts(opened)

        return Job.model_validate(self._c._send(send).json())

    def get(self, job_id: str, *, timeout: float | None = None) -> Job:
        return Job.model_validate(self._c._request("GET", f"/v1/jobs/{job_id}", timeout=timeout).json())

    def wait(self, job_id: str, *, timeout: float | None = 600.0, on_progress: Progress | None = None) -> Job:
        """Wait until the job is finished, long-polling the service (each request returns as
        soon as the job changes), with backoff between requests from 10 ms to 2 s."""
        deadline = None if timeout is None else time.monotonic() + timeout
        delay = 0.01
        while True:
            job = self._get_waiting(job_id, long_poll_hold(deadline))
            if on_progress:
                on_progress(job)
            if job.done:
                return job
            if deadline is not None and time.monotonic() >= deadline:
                raise WaitTimeoutError(f"job {job_id} still {job.status} after {timeout} s")
            time.sleep(delay)
            delay = next_poll(delay)

    def _get_waiting(self, job_id: str, hold_s: float) -> Job:
        resp = self._c._request("GET", f"/v1/jobs/{job_id}", params={"wait": hold_s}, timeout=hold_s + 30)
        return Job.model_validate(resp.json())

    def result(self, job_id: str, *, timeout: float | None = 600.0) -> Any:
        """Wait for the job and return its result, typed by its kind (``MotionResult`` for
        linescan-motion; see ``tumblescan_client.results``); JobFailedError otherwise."""
        return typed_result(self.wait(job_id, timeout=timeout))

    def artifacts(self, job_id: str, *, timeout: float | None = None) -> list[Artifact]:
        """The files a succeeded job has (its kind's artifacts and its report)."""
        resp = self._c._request("GET", f"/v1/jobs/{job_id}/artifacts", timeout=timeout)
        return [Artifact.model_validate(a) for a in resp.json()]

    def download_artifact(
        self, job_id: str, name: str, path: str | os.PathLike[str], *, timeout: float | None = None
    ) -> Path:
        """Stream one artifact of a succeeded job to ``path``."""
        return self._download(f"/v1/jobs/{job_id}/artifacts/{name}", {}, path, timeout)

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
            try:
                with open(tmp, "wb") as fh:
                    for chunk in resp.iter_bytes(1 << 20):
                        fh.write(chunk)
            finally:
                resp.close()
            return resp

        try:
            self._c._send(send)
            tmp.replace(out)
        except BaseException:  # no half-written .part left beside the target
            tmp.unlink(missing_ok=True)
            raise
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


class AsyncJobs:
    """``async_client.jobs``: the same operations as :class:`Jobs`, awaitable."""

    def __init__(self, client: AsyncClient) -> None:
        self._c = client

    async def create(
        self,
        kind: str = DEFAULT_KIND,
        input: dict[str, Any] | None = None,
        *,
        options: dict[str, Any] | None = None,
        tracks: dict[str, Any] | None = None,
        timeout: float | None = None,
    ) -> Job:
        body = create_body(kind, input, tracks, options)
        return Job.model_validate((await self._c._request("POST", "/v1/jobs", json=body, timeout=timeout)).json())

    async def upload(
        self,
        kind: str | os.PathLike[str],
        files: Files | None = None,
        *,
        options: dict[str, Any] | None = None,
        cloud: PathLike | None = None,
        truth: PathLike | None = None,
        timeout: float | None = None,
        **legacy: Any,
    ) -> Job:
        kind_name, parts = upload_request(kind, files, {"cloud": cloud, "truth": truth}, legacy.pop("kind", None))
        if legacy:
            raise TypeError(f"unexpected argument(s): {', '.join(legacy)}")

        async def send() -> httpx.Response:
            opened = open_parts(parts)
            data = {"options": json.dumps(options or {}), "kind": kind_name}
            try:
                return await self._c._http.request(
                    "POST", "/v1/jobs/upload", files=opened, data=data, timeout=timeout or httpx.USE_CLIENT_DEFAULT
                )
            finally:
                close_parts(opened)

        return Job.model_validate((await self._c._send(send)).json())

    async def get(self, job_id: str, *, timeout: float | None = None) -> Job:
        return Job.model_validate((await self._c._request("GET", f"/v1/jobs/{job_id}", timeout=timeout)).json())

    async def wait(self, job_id: str, *, timeout: float | None = 600.0, on_progress: Progress | None = None) -> Job:
        deadline = None if timeout is None else time.monotonic() + timeout
        delay = 0.01
        while True:
            hold = long_poll_hold(deadline)
            resp = await self._c._request("GET", f"/v1/jobs/{job_id}", params={"wait": hold}, timeout=hold + 30)
            job = Job.model_validate(resp.json())
            if on_progress:
                on_progress(job)
            if job.done:
                return job
            if deadline is not None and time.monotonic() >= deadline:
                raise WaitTimeoutError(f"job {job_id} still {job.status} after {timeout} s")
            await asyncio.sleep(delay)
            delay = next_poll(delay)

    async def result(self, job_id: str, *, timeout: float | None = 600.0) -> Any:
        return typed_result(await self.wait(job_id, timeout=timeout))

    async def artifacts(self, job_id: str, *, timeout: float | None = None) -> list[Artifact]:
        resp = await self._c._request("GET", f"/v1/jobs/{job_id}/artifacts", timeout=timeout)
        return [Artifact.model_validate(a) for a in resp.json()]

    async def download_artifact(
        self, job_id: str, name: str, path: str | os.PathLike[str], *, timeout: float | None = None
    ) -> Path:
        return await self._download(f"/v1/jobs/{job_id}/artifacts/{name}", {}, path, timeout)

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
            try:
                with open(tmp, "wb") as fh:
                    async for chunk in resp.aiter_bytes(1 << 20):
                        fh.write(chunk)
            finally:
                await resp.aclose()
            return resp

        try:
            await self._c._send(send)
            tmp.replace(out)
        except BaseException:  # no half-written .part left beside the target
            tmp.unlink(missing_ok=True)
            raise
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
