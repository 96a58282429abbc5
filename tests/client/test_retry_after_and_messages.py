"""``Retry-After`` the client cannot parse or will not wait for, and short error messages for
bodies that are not the service's (sync and async alike, against ``httpx.MockTransport``)."""

from __future__ import annotations

import asyncio
import email.utils
import time
from collections.abc import Callable, Iterator
from types import SimpleNamespace
from typing import Any

import httpx
import pytest

from tumblescan_client import (
    APIStatusError,
    AsyncClient,
    Client,
    InternalServerError,
    NotFoundError,
    RetryPolicy,
    ServiceUnavailableError,
)
from tumblescan_client import _client as client_module
from tumblescan_client._retry import retry_after

JOB = {
    "id": "a", "kind": "linescan-motion", "status": "queued", "progress": 0.0, "stage": "queued",
    "created_at": "2026-01-01T00:00:00Z", "started_at": None, "finished_at": None,
    "error": None, "result": None, "artifacts": {"cloud": None},
}  # fmt: skip
POLICY = RetryPolicy(max_retries=1, initial_delay_s=0.01, max_delay_s=0.01)
Handler = Callable[[httpx.Request], httpx.Response]


@pytest.fixture
def slept(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[float]]:
    """The client's sleeps between tries, recorded instead of slept (sync and async)."""
    waits: list[float] = []

    async def asleep(s: float) -> None:
        waits.append(s)

    monkeypatch.setattr(client_module, "time", SimpleNamespace(sleep=waits.append))
    monkeypatch.setattr(client_module, "asyncio", SimpleNamespace(sleep=asleep))
    yield waits


def answers(*responses: httpx.Response) -> tuple[Handler, list[httpx.Request]]:
    """A handler giving ``responses`` in turn (the last one from then on), and the requests seen."""
    seen: list[httpx.Request] = []

    def handle(request: httpx.Request) -> httpx.Response:
        seen.append(request)
        return responses[min(len(seen), len(responses)) - 1]

    return handle, seen


def get_job(handler: Handler, *, use_async: bool, policy: RetryPolicy = POLICY) -> Any:
    if not use_async:
        with Client("http://svc", retry=policy, transport=httpx.MockTransport(handler)) as client:
            return client.jobs.get("a")

    async def go() -> Any:
        async with AsyncClient("http://svc", retry=policy, transport=httpx.MockTransport(handler)) as client:
            return await client.jobs.get("a")

    return asyncio.run(go())


def busy(after: str) -> httpx.Response:
    return httpx.Response(
        503, json={"detail": {"code": "busy", "message": "try later"}}, headers={"Retry-After": after}
    )


both = pytest.mark.parametrize("use_async", [False, True], ids=["sync", "async"])


@both
def test_an_unparseable_retry_after_is_ignored_and_the_backoff_applies(use_async: bool, slept: list[float]) -> None:
    # parsedate_to_datetime raised a raw ValueError out of the client.
    handler, seen = answers(busy("soon"), httpx.Response(200, json=JOB))
    assert get_job(handler, use_async=use_async).id == "a"
    assert len(seen) == 2 and len(slept) == 1 and 0 < slept[0] <= 0.01
    handler, seen = answers(busy("soon"))
    with pytest.raises(ServiceUnavailableError) as exc:
        get_job(handler, use_async=use_async)
    assert len(seen) == 2 and exc.value.code == "busy" and exc.value.retry_after is None


@both
def test_a_retry_after_beyond_the_limit_raises_at_once(use_async: bool, slept: list[float]) -> None:
    # It was replaced by the ~10 ms backoff and the request tried again.
    handler, seen = answers(busy("3600"), httpx.Response(200, json=JOB))
    with pytest.raises(ServiceUnavailableError) as exc:
        get_job(handler, use_async=use_async)
    assert len(seen) == 1 and slept == []
    assert exc.value.retry_after == 3600 and exc.value.response.headers["Retry-After"] == "3600"


@both
def test_a_retry_after_within_the_limit_is_waited_for(use_async: bool, slept: list[float]) -> None:
    in_30s = email.utils.formatdate(time.time() + 30, usegmt=True)
    handler, seen = answers(busy("5"), busy(in_30s), httpx.Response(200, json=JOB))
    assert get_job(handler, use_async=use_async, policy=RetryPolicy(max_retries=2, initial_delay_s=0.01)).id == "a"
    assert len(seen) == 3 and slept[0] == 5.0 and 25 < slept[1] <= 30


@pytest.mark.parametrize(
    ("header", "seconds"),
    [
        ("soon", None),
        ("", None),
        ("nan", None),
        ("inf", None),
        ("-5", None),
        ("Wed, 31 Feb 2015 07:28:00 GMT", None),  # no such day
        ("Wed, 21 Oct 2015 07:28:00 GMT", 0.0),  # in the past: now
        ("7", 7.0),
        ("1.5", 1.5),
    ],
)
def test_retry_after_never_raises(header: str, seconds: float | None) -> None:
    assert retry_after(httpx.Response(503, headers={"Retry-After": header})) == seconds


def test_a_retry_after_date_without_a_zone_is_utc() -> None:
    value = email.utils.formatdate(time.time() + 20).replace("+0000", "-0000")
    after = retry_after(httpx.Response(503, headers={"Retry-After": value}))
    assert after is not None and 15 < after <= 20


NGINX_502 = (
    "<html>\r\n<head><title>502 Bad Gateway</title></head>\r\n<body>\r\n<center><h1>502 Bad Gateway</h1></center>\r\n"
    + "<!-- a padding comment -->\r\n" * 70
    + "<hr><center>nginx</center>\r\n</body>\r\n</html>\r\n"
)


def error_of(response: httpx.Response, *, use_async: bool) -> APIStatusError:
    with pytest.raises(APIStatusError) as exc:
        get_job(answers(response)[0], use_async=use_async, policy=RetryPolicy(max_retries=0))
    return exc.value


@both
def test_an_empty_non_json_error_says_its_status_and_reason(use_async: bool) -> None:
    # It was "404 :".
    exc = error_of(httpx.Response(404, text=""), use_async=use_async)
    assert isinstance(exc, NotFoundError) and str(exc) == "404 Not Found"
    assert exc.code == "" and exc.message == "" and exc.field is None


@both
def test_a_proxy_html_page_is_left_out_of_the_message(use_async: bool) -> None:
    # The whole 2 KB page was the message.
    assert len(NGINX_502) > 2000
    for headers in ({"Content-Type": "text/html"}, {"Content-Type": "text/plain"}):
        exc = error_of(httpx.Response(502, content=NGINX_502.encode(), headers=headers), use_async=use_async)
        assert isinstance(exc, InternalServerError) and str(exc) == "502 Bad Gateway"
        assert exc.response.text == NGINX_502  # still there for whoever wants it


@both
def test_a_text_body_is_cut_to_one_short_line(use_async: bool) -> None:
    exc = error_of(httpx.Response(404, text="no route\n\tfor  /v1/jobs/a\n"), use_async=use_async)
    assert str(exc) == "404 Not Found: no route for /v1/jobs/a"
    exc = error_of(
        httpx.Response(500, text="Traceback (most recent call last):\n" + "  frame\n" * 2000), use_async=use_async
    )
    message = str(exc)
    assert message.startswith("500 Internal Server Error: Traceback (most recent call last): frame frame")
    assert "\n" not in message and message.endswith("...") and len(message) <= 240


@both
def test_service_errors_and_other_json_read_as_before(use_async: bool) -> None:
    body = {"detail": {"code": "not_found", "message": "no job a", "field": None}}
    exc = error_of(httpx.Response(404, json=body), use_async=use_async)
    assert str(exc) == "404 not_found: no job a" and exc.code == "not_found" and exc.message == "no job a"
    exc = error_of(httpx.Response(404, json={"detail": "Not Found"}), use_async=use_async)
    assert str(exc) == "404 Not Found: Not Found" and exc.code == ""
    exc = error_of(httpx.Response(502, json=["upstream", "down"]), use_async=use_async)
    assert str(exc) == '502 Bad Gateway: ["upstream","down"]'


def test_a_missing_artifact_is_gone_and_a_cancel_request_shows() -> None:
    from tumblescan_client import GoneError

    gone = {"detail": {"code": "artifact_missing", "message": "job a's cloud (cloud.ply) is no longer in the store"}}
    handle, _ = answers(httpx.Response(410, json=gone))
    with (
        Client("http://t", transport=httpx.MockTransport(handle), retry=POLICY) as client,
        pytest.raises(GoneError) as exc,
    ):
        client.jobs.get("a")
    assert exc.value.status_code == 410 and "no longer in the store" in str(exc.value)
    handle, _ = answers(httpx.Response(200, json={**JOB, "status": "running", "cancel_requested": True}))
    with Client("http://t", transport=httpx.MockTransport(handle), retry=POLICY) as client:
        assert client.jobs.get("a").cancel_requested
