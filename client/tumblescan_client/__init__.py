"""Client for the Tumblescan service: ``Client`` and ``AsyncClient``.

from tumblescan_client import Client
with Client("http://127.0.0.1:8000") as client:
    job = client.jobs.upload("tracks.json")
    result = client.jobs.result(job.id)
    print(result.spin.rate_deg_s, "+-", result.uncertainty.spin_rate_deg_s)
"""

from ._client import AsyncClient, Client
from ._retry import RetryPolicy
from .errors import (
    APIConnectionError,
    APIStatusError,
    APITimeoutError,
    AuthenticationError,
    BadRequestError,
    ConflictError,
    InternalServerError,
    JobFailedError,
    NotFoundError,
    PayloadTooLargeError,
    PermissionDeniedError,
    RateLimitError,
    ServiceUnavailableError,
    TumblescanError,
    UnprocessableEntityError,
    WaitTimeoutError,
)
from .models import Job, JobPage, MotionResult

__all__ = [
    "APIConnectionError",
    "APIStatusError",
    "APITimeoutError",
    "AsyncClient",
    "AuthenticationError",
    "BadRequestError",
    "Client",
    "ConflictError",
    "InternalServerError",
    "Job",
    "JobFailedError",
    "JobPage",
    "MotionResult",
    "NotFoundError",
    "PayloadTooLargeError",
    "PermissionDeniedError",
    "RateLimitError",
    "RetryPolicy",
    "ServiceUnavailableError",
    "TumblescanError",
    "UnprocessableEntityError",
    "WaitTimeoutError",
]
