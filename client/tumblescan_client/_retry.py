"""Retry policy shared by the sync and async clients: capped exponential backoff with jitter,
honouring ``Retry-After``."""

from __future__ import annotations

import email.utils
import math
import random
import time
from dataclasses import dataclass
from datetime import timezone

import httpx

RETRY_STATUSES = frozenset({408, 429, 500, 502, 503, 504})


@dataclass(frozen=True)
class RetryPolicy:
    max_retries: int = 3
    initial_delay_s: float = 0.5
    max_delay_s: float = 8.0
    # A Retry-After longer than this is not waited for: the error is raised instead.
    max_retry_after_s: float = 60.0

    def should_retry(self, attempt: int, response: httpx.Response | None) -> bool:
        if attempt >= self.max_retries:
            return False
        if response is None:
            return True
        if response.status_code not in RETRY_STATUSES:
            return False
        after = retry_after(response)
        return after is None or after <= self.max_retry_after_s

    def delay(self, attempt: int, response: httpx.Response | None) -> float:
        """Seconds before the next try: the response's ``Retry-After`` when there is one within
        ``max_retry_after_s`` (``should_retry`` refuses a longer one), else the backoff."""
        after = retry_after(response)
        if after is not None and after <= self.max_retry_after_s:
            return after
        base = min(self.initial_delay_s * (2**attempt), self.max_delay_s)
        return base * (1 - 0.25 * random.random())


def retry_after(response: httpx.Response | None) -> float | None:
    """Seconds the response asks the client to wait (``Retry-After-Ms`` or ``Retry-After``, as
    seconds or an HTTP date; one in the past is 0); ``None`` when absent or unparseable."""
    if response is None:
        return None
    value = response.headers.get("retry-after-ms")
    if value:
        seconds = _seconds(value)
        if seconds is not None:
            return seconds / 1000
    value = response.headers.get("retry-after")
    if not value:
        return None
    seconds = _seconds(value)
    if seconds is not None:
        return seconds
    try:
        parsed = email.utils.parsedate_to_datetime(value)
    except (TypeError, ValueError, IndexError, OverflowError):
        return None  # not a date either: ignored, the backoff applies
    if parsed.tzinfo is None:  # "-0000": UTC by RFC 5322
        parsed = parsed.replace(tzinfo=timezone.utc)  # noqa: UP017 (datetime.UTC is 3.11+; the client supports 3.10)
    return max(parsed.timestamp() - time.time(), 0.0)


def _seconds(value: str) -> float | None:
    try:
        seconds = float(value)
    except ValueError:
        return None
    return seconds if math.isfinite(seconds) and seconds >= 0 else None  # "-5", "nan": not a delay
