"""What the sync and async clients share: configuration, retries, request bodies and files."""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, BinaryIO

import httpx
from pydantic import BaseModel

from ._retry import RetryPolicy
from .errors import APIConnectionError, APITimeoutError, JobFailedError, error_for
from .models import Job
from .results import result_model

DEFAULT_URL = "http://127.0.0.1:8000"
DEFAULT_TIMEOUT = httpx.Timeout(30.0, connect=5.0)
Progress = Callable[[Job], None]


def configure(
    base_url: str | None, api_key: str | None, max_retries: int, retry: RetryPolicy | None
) -> tuple[str, dict[str, str], RetryPolicy]:
    """Base URL, headers and retry policy, from the arguments or the environment."""
    url = base_url or os.environ.get("TUMBLESCAN_URL") or DEFAULT_URL
    scheme = url.split("://", 1)[0].lower() if "://" in url else ""
    if scheme not in ("http", "https"):
        # Refused here, once: httpx would fail every request with a transport error, retried with backoff.
        raise ValueError(f"service URL {url!r} must start with http:// or https://")
    key = api_key or os.environ.get("TUMBLESCAN_API_KEY")
    headers = {"User-Agent": "tumblescan-client/0.1"}
    if key:
        headers["Authorization"] = f"Bearer {key}"
    return url, headers, retry or RetryPolicy(max_retries=max_retries)


def transport_error(exc: httpx.TransportError) -> Exception:
    if isinstance(exc, httpx.TimeoutException):
        return APITimeoutError(f"request timed out: {exc}")
    return APIConnectionError(f"cannot reach the service: {exc}")


def retry_delay(policy: RetryPolicy, attempt: int, resp: httpx.Response | None, error: Exception | None) -> float:
    """Seconds to wait before the next try; raises the final error when none is left."""
    if not policy.should_retry(attempt, resp):
        if resp is not None:
            raise error_for(resp)
        assert error is not None
        raise error
    return policy.delay(attempt, resp)


PathLike = str | os.PathLike[str]
Files = Mapping[str, PathLike | Sequence[PathLike]]
DEFAULT_KIND = "linescan-motion"


def create_body(
    kind: str, input: dict[str, Any] | None, tracks: dict[str, Any] | None, options: dict[str, Any] | None
) -> dict[str, Any]:
    """The JSON of POST /v1/jobs; ``tracks=`` is the linescan-motion shorthand for ``input``."""
    if (input is None) == (tracks is None):
        raise TypeError("give the job's input as input=... (or tracks=... for linescan-motion)")
    return {"kind": kind, "input": input if input is not None else {"tracks": tracks}, "options": options or {}}


def upload_request(
    kind_or_path: str | os.PathLike[str],
    files: Files | None,
    legacy: dict[str, PathLike | None],
    kind: str | None,
) -> tuple[str, dict[str, list[PathLike]]]:
    """The kind and its files by part. ``upload(kind, files={...})``, or as before the kinds
    came, ``upload(path, cloud=..., truth=...)`` for linescan-motion's ``file``."""
    if files is None:
        named: dict[str, list[PathLike]] = {"file": [kind_or_path]}
        named |= {k: [v] for k, v in legacy.items() if v is not None}
        return kind or DEFAULT_KIND, named
    if kind is not None or any(v is not None for v in legacy.values()):
        raise TypeError("with files=..., give the kind as the first argument and every file in files")
    parts = {k: [v] if isinstance(v, str | os.PathLike) else list(v) for k, v in files.items()}
    return str(kind_or_path), parts


def open_parts(parts: dict[str, list[PathLike]]) -> list[tuple[str, tuple[str, BinaryIO, str]]]:
    """Multipart file parts (several may share a field); the caller closes them."""
    opened: list[tuple[str, tuple[str, BinaryIO, str]]] = []
    try:
        for field, paths in parts.items():
            for p in paths:
                opened.append((field, (Path(p).name, open(p, "rb"), "application/octet-stream")))  # noqa: SIM115
    except BaseException:
        close_parts(opened)
        raise
    return opened


def close_parts(files: list[tuple[str, tuple[str, BinaryIO, str]]]) -> None:
    for _, (_, fh, _) in files:
        fh.close()


def typed_result(job: Job) -> BaseModel:
    if job.status != "succeeded" or job.result is None:
        raise JobFailedError(job)
    return result_model(job.kind).model_validate(job.result)


def next_poll(delay: float) -> float:
    return min(delay * 1.5, 2.0)


LONG_POLL_S = 10.0


def long_poll_hold(deadline: float | None) -> float:
    """How long the service may hold one long-poll request."""
    if deadline is None:
        return LONG_POLL_S
    return round(max(0.0, min(LONG_POLL_S, deadline - time.monotonic())), 3)
