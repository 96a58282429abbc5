"""``Client`` and ``AsyncClient``: twins over httpx that send with retries and hold the resources."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from typing import Any

import httpx

from ._jobs import AsyncJobs, Jobs
from ._kinds import AsyncKinds, Kinds
from ._requests import DEFAULT_TIMEOUT, configure, retry_delay, transport_error
from ._retry import RetryPolicy


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
        url, headers, self.retry = configure(base_url, api_key, max_retries, retry)
        self._http = httpx.Client(base_url=url, headers=headers, timeout=timeout, transport=transport)
        self.jobs = Jobs(self)
        self.kinds = Kinds(self)

    def _request(self, method: str, path: str, *, timeout: float | None = None, **kw: Any) -> httpx.Response:
        return self._send(lambda: self._http.request(method, path, timeout=timeout or httpx.USE_CLIENT_DEFAULT, **kw))

    def _send(self, send: Callable[[], httpx.Response]) -> httpx.Response:
        attempt = 0
        while True:
            try:
                resp, error = send(), None
            except httpx.TransportError as exc:
                resp, error = None, transport_error(exc)
            if resp is not None and resp.status_code < 400:
                return resp
            time.sleep(retry_delay(self.retry, attempt, resp, error))
            attempt += 1

    def close(self) -> None:
        self._http.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


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
        url, headers, self.retry = configure(base_url, api_key, max_retries, retry)
        self._http = httpx.AsyncClient(base_url=url, headers=headers, timeout=timeout, transport=transport)
        self.jobs = AsyncJobs(self)
        self.kinds = AsyncKinds(self)

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
                resp, error = None, transport_error(exc)
            if resp is not None and resp.status_code < 400:
                return resp
            await asyncio.sleep(retry_delay(self.retry, attempt, resp, error))
            attempt += 1

    async def close(self) -> None:
        await self._http.aclose()

    async def __aenter__(self) -> AsyncClient:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()
