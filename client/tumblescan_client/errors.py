"""One exception per HTTP status the service uses, plus connection and timeout errors."""

from __future__ import annotations

from typing import Any

import httpx


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
    from its error body."""

    status_code: int = 0

    def __init__(self, response: httpx.Response) -> None:
        self.response = response
        self.status_code = response.status_code
        detail: Any = None
        try:
            detail = response.json().get("detail")
        except ValueError:
            detail = response.text
        if isinstance(detail, dict):
            self.code = str(detail.get("code", ""))
            self.message = str(detail.get("message", ""))
            self.field = detail.get("field")
        else:
            self.code, self.message, self.field = "", str(detail), None
        super().__init__(f"{self.status_code} {self.code}: {self.message}".strip())


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
