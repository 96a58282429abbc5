"""One exception per HTTP status the service uses, plus connection and timeout errors."""

from __future__ import annotations

from typing import Any

import httpx

from ._retry import retry_after


class TumblescanError(Exception):
    """Base of every error this client raises."""


class APIConnectionError(TumblescanError):
    """The service could not be reached (after retries)."""


class APITimeoutError(APIConnectionError):
    """The request timed out (after retries)."""


class JobFailedError(TumblescanError):
    """``jobs.result`` on a job that ended ``failed`` or ``cancelled``."""

    def __init__(self, job: Any) -> None:
        err = job.error
        super().__init__(f"job {job.id} {job.status}" + (f": {err.code}: {err.message}" if err else ""))
        self.job = job


class WaitTimeoutError(TumblescanError):
    """``jobs.wait`` gave up before the job finished."""


class APIStatusError(TumblescanError):
    """The service answered with an error status; ``code``, ``message`` and ``field`` come
    from its error body. A body that is not the service's (a proxy's page, plain text) gives
    an empty ``code`` and a one-line ``message``: the start of its text, or nothing for HTML.
    ``retry_after`` is the seconds the answer's ``Retry-After`` asked for, or ``None``."""

    status_code: int = 0

    def __init__(self, response: httpx.Response) -> None:
        self.response = response
        self.status_code = response.status_code
        self.retry_after = retry_after(response)
        detail: Any = None
        try:
            body = response.json()
        except ValueError:
            body = None
        if isinstance(body, dict):
            detail = body.get("detail")
        if isinstance(detail, dict):
            self.code = str(detail.get("code", ""))
            self.message = str(detail.get("message", ""))
            self.field = detail.get("field")
        else:
            self.code, self.field = "", None
            self.message = _one_line(detail if isinstance(detail, str) else _body_text(response))
        head = f"{self.status_code} {self.code or response.reason_phrase}".strip()
        super().__init__(f"{head}: {self.message}" if self.message else head)


_SNIPPET_CHARS = 200


def _body_text(response: httpx.Response) -> str:
    """The body as text, or "" when it is HTML (a proxy's or server's error page)."""
    text = response.text
    start = text.lstrip()[:15].lower()
    if "html" in response.headers.get("content-type", "").lower() or start.startswith(("<!doctype", "<html")):
        return ""
    return text[: _SNIPPET_CHARS * 8]


def _one_line(text: str) -> str:
    """``text`` on one line (whitespace and control characters collapsed), cut to about 200 characters."""
    line = " ".join("".join(c if c.isprintable() else " " for c in text).split())
    return line if len(line) <= _SNIPPET_CHARS else line[: _SNIPPET_CHARS - 3].rstrip() + "..."


class BadRequestError(APIStatusError):
    status_code = 400


class AuthenticationError(APIStatusError):
    status_code = 401


class PermissionDeniedError(APIStatusError):
    status_code = 403


class NotFoundError(APIStatusError):
    status_code = 404


class ConflictError(APIStatusError):
    status_code = 409


class GoneError(APIStatusError):
    """A finished job's file is no longer in the service's store (``artifact_missing``)."""

    status_code = 410


class PayloadTooLargeError(APIStatusError):
    status_code = 413


class UnprocessableEntityError(APIStatusError):
    status_code = 422


class RateLimitError(APIStatusError):
    status_code = 429


class InternalServerError(APIStatusError):
    status_code = 500


class ServiceUnavailableError(APIStatusError):
    status_code = 503


_BY_STATUS: dict[int, type[APIStatusError]] = {
    c.status_code: c
    for c in (
        BadRequestError,
        AuthenticationError,
        PermissionDeniedError,
        NotFoundError,
        ConflictError,
        GoneError,
        PayloadTooLargeError,
        UnprocessableEntityError,
        RateLimitError,
        InternalServerError,
        ServiceUnavailableError,
    )
}


def error_for(response: httpx.Response) -> APIStatusError:
    cls = _BY_STATUS.get(response.status_code)
    if cls is None:
        cls = InternalServerError if response.status_code >= 500 else APIStatusError
    return cls(response)
