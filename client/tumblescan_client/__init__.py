"""Client for the Tumblescan service: ``Client`` and ``AsyncClient``.

from tumblescan_client import Client
with Client("http://127.0.0.1:8000") as client:
    job = client.jobs.upload("linescan-motion", files={"file": "tracks.json"})
    result = client.jobs.result(job.id)  # typed by the job's kind
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
    GoneError,
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
from .models import Artifact, Job, JobPage, Kind, KindSummary
from .results import RESULT_MODELS, MotionResult, UnknownResult, result_model

__all__ = [
    "RESULT_MODELS",
    "APIConnectionError",
    "APIStatusError",
    "APITimeoutError",
    "Artifact",
    "AsyncClient",
    "AuthenticationError",
    "BadRequestError",
    "Client",
    "ConflictError",
    "GoneError",
    "InternalServerError",
    "Job",
    "JobFailedError",
    "JobPage",
    "Kind",
    "KindSummary",
    "MotionResult",
    "NotFoundError",
    "PayloadTooLargeError",
    "PermissionDeniedError",
    "RateLimitError",
    "RetryPolicy",
    "ServiceUnavailableError",
    "TumblescanError",
    "UnknownResult",
    "UnprocessableEntityError",
    "WaitTimeoutError",
    "result_model",
]
