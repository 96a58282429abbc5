"""Bad submissions a user makes, answered at the door: a 422 whose body names the field, never
a 500. In-process (FastAPI's TestClient, no workers): every check here happens at submission."""

from __future__ import annotations

import json
from typing import Any

import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient

from tumblescan.api import errors
from tumblescan.errors import MalformedInputError
from tumblescan.jobs.kind import Submission
from tumblescan.jobs.service import _accept

DEEP = "[" * 100_000 + "]" * 100_000  # past Python's JSON recursion limit


@pytest.fixture
def client(api: TestClient) -> TestClient:
    return api


def detail(r: Any, status: int = 422) -> dict[str, Any]:
    assert r.status_code == status, r.text
    body: dict[str, Any] = r.json()["detail"]
    return body


def markers_doc(frame: int) -> dict[str, Any]:
    obs = [
        {"frame": f, "t": f / 50, "track": f"T{k}", "xyz": [0.1 * k, 0.2 * (k % 2), 1.0 + 0.05 * f]}
        for f in range(4)
        for k in range(4)
    ]
    obs[0]["frame"] = frame
    return {"format": "tumblescan.markers.v1", "units": {"length": "m", "time": "s"}, "observations": obs}


@pytest.mark.parametrize(
    ("kind", "files"),
    [
        ("bearings", {"input": ("input.json", DEEP)}),
        ("linescan-motion", {"file": ("tracks.json", '{"observations": ' + DEEP + "}")}),
        ("marker-pose-graph", {"markers": ("markers.json", '{"observations": ' + DEEP + "}")}),
        ("panel-axis", {"meta": ("meta.json", '{"a": ' + DEEP + "}"), "image": ("image.png", b"\x89PNG")}),
    ],
)
def test_json_nested_past_the_parsers_limit_is_a_422_naming_the_part(
    client: TestClient, kind: str, files: dict[str, Any]
) -> None:
    d = detail(client.post("/v1/jobs/upload", data={"kind": kind}, files=files))
    assert "nests too deeply" in d["message"] and d["field"]


def test_deeply_nested_options_are_a_422_naming_options(client: TestClient) -> None:
    r = client.post("/v1/jobs/upload", data={"kind": "bearings", "options": DEEP}, files={"input": ("i.json", b"{}")})
    d = detail(r)
    assert d["field"] == "options" and "nests too deeply" in d["message"]


def test_an_input_a_reader_chokes_on_is_a_422_not_a_500(client: TestClient) -> None:
    # A frame number too large for an int64 array once made the marker reader raise OverflowError.
    # Whether the reader names the frame itself or the service's safety net answers, it is a 422.
    r = client.post("/v1/jobs", json={"kind": "marker-pose-graph", "input": markers_doc(10**30)})
    d = detail(r)
    assert d["code"] in ("malformed_input", "invalid_input") and d["field"]


@pytest.mark.parametrize("field", ["kind", "options"])
def test_kind_or_options_given_twice_is_refused_not_last_one_wins(client: TestClient, field: str) -> None:
    values = {"kind": ("bearings", "linescan-motion"), "options": ("{}", '{"seed": 1}')}[field]
    data = [(field, v) for v in values] + ([] if field == "kind" else [("kind", "bearings")])
    body, ctype = _multipart(data, [("input", "input.json", b"{}")])
    d = detail(client.post("/v1/jobs/upload", content=body, headers={"content-type": ctype}))
    assert d["field"] == field and "2 times" in d["message"]


def test_two_files_of_one_part_with_the_same_name_are_refused(client: TestClient) -> None:
    png = b"\x89PNG\r\n\x1a\n"
    files = [("meta", ("meta.json", b"{}")), ("frames", ("f0.png", png)), ("frames", ("f0.png", png))]
    d = detail(client.post("/v1/jobs/upload", data={"kind": "spin-from-images"}, files=files))
    assert d["field"] == "frames" and "two files named f0.png" in d["message"]


def test_option_and_request_errors_carry_the_field(client: TestClient) -> None:
    r = client.post("/v1/jobs/upload", data={"kind": "bearings", "options": '{"zz": 1}'}, files={"input": ("i", b"{}")})
    d = detail(r)
    assert d["code"] == "invalid_options" and d["field"] == "options.zz"
    d = detail(client.post("/v1/jobs", json={"kind": "bearings", "input": {}, "extra": 1}))
    assert d["field"] == "body.extra" and d["message"] == "body.extra: unknown field"
    assert detail(client.get("/v1/jobs", params={"limit": "x"}))["field"] == "query.limit"


@pytest.mark.parametrize(
    ("content", "words"),
    [
        (b'{"kind": "bearings", "input": ' + DEEP.encode() + b"}", "body: the JSON nests too deeply to read"),
        (b'{"kind": "bearings", "input": {"n": ' + b"7" * 5000 + b"}}", "body: a number in the JSON is too long"),
        (b'{"kind": "\xff"}', "body: not valid JSON"),
        (b"\xff\xfe\x00", "body: not valid JSON"),
    ],
)
def test_a_json_body_the_parser_cannot_read_is_a_422_naming_the_body(
    client: TestClient, content: bytes, words: str
) -> None:
    # As the upload path says of its parts' JSON; FastAPI's own answer was 400 "There was an
    # error parsing the body".
    r = client.post("/v1/jobs", content=content, headers={"content-type": "application/json"})
    d = detail(r)
    assert d["code"] == "malformed_input" and d["field"] == "body" and words in d["message"], d


def test_a_body_of_the_other_endpoints_type_names_the_type_each_takes(client: TestClient) -> None:
    d = detail(client.post("/v1/jobs/upload", json={"kind": "bearings", "input": {}}))
    assert d["code"] == "wrong_content_type" and d["field"] == "body"
    assert "takes multipart/form-data, not application/json" in d["message"] and "POST /v1/jobs" in d["message"]
    d = detail(client.post("/v1/jobs", content=b"kind=bearings", headers={"content-type": "text/plain"}))
    assert d["code"] == "wrong_content_type" and d["field"] == "body"
    assert "takes application/json, not text/plain" in d["message"] and "/v1/jobs/upload" in d["message"]
    d = detail(client.post("/v1/jobs/upload", content=b"x"))
    assert "not a body without a Content-Type" in d["message"]
    # A form without a file is still the form's own problem.
    d = detail(client.post("/v1/jobs/upload", data={"kind": "bearings"}))
    assert d["field"] == "file" and "GET /v1/kinds/bearings lists its parts" in d["message"]


@pytest.mark.parametrize(
    ("kind", "part", "name"),
    [
        ("linescan-motion", "file", "frames.ply"),
        ("linescan-motion", "file", "frames.npz"),
        ("linescan-motion", "file", "tracks.csv"),
        ("bearings", "input", "input.json"),
    ],
)
def test_an_empty_file_is_said_to_be_empty(client: TestClient, kind: str, part: str, name: str) -> None:
    # Not "is not a PLY file (its first bytes say otherwise)": an empty file has no first bytes.
    d = detail(client.post("/v1/jobs/upload", data={"kind": kind}, files={part: (name, b"")}))
    assert d["field"] == part and d["message"] == f"'{part}': {name} is empty (0 bytes)"


@pytest.mark.parametrize("wait", ["nan", "inf", "-inf"])
def test_a_wait_that_is_not_a_finite_number_says_so(client: TestClient, wait: str) -> None:
    job = client.app.state.service.store.create(kind="bearings", options={}, input={}, owner=None)  # type: ignore[attr-defined]
    d = detail(client.get(f"/v1/jobs/{job.id}", params={"wait": wait}))
    assert d["field"] == "query.wait" and "finite number" in d["message"], d


def _multipart(fields: list[tuple[str, str]], files: list[tuple[str, str, bytes]]) -> tuple[bytes, str]:
    """A multipart body by hand: httpx merges repeated text fields into one list, which is the
    very case under test."""
    b = b"qaboundary"
    out = b""
    for name, value in fields:
        out += b"--" + b + f'\r\nContent-Disposition: form-data; name="{name}"\r\n\r\n{value}\r\n'.encode()
    for name, filename, data in files:
        head = f'\r\nContent-Disposition: form-data; name="{name}"; filename="{filename}"\r\n\r\n'.encode()
        out += b"--" + b + head + data + b"\r\n"
    return out + b"--" + b + b"--\r\n", "multipart/form-data; boundary=qaboundary"


class _Choking:
    """A kind whose reader raises what no reader should: the service must still answer 422."""

    name = "choking"

    def __init__(self, exc: BaseException) -> None:
        self.exc = exc

    def accept(self, sub: Submission) -> dict[str, str]:
        raise self.exc


@pytest.mark.parametrize(
    ("exc", "words"),
    [(RecursionError(), "nests too deeply"), (OverflowError("too large"), "OverflowError: too large")],
)
def test_accept_turns_a_readers_exception_into_malformed_input(exc: BaseException, words: str) -> None:
    with pytest.raises(MalformedInputError, match=words) as info:
        _accept(_Choking(exc), None, "markers")  # type: ignore[arg-type]
    assert info.value.field == "markers"


def test_accept_keeps_storage_errors_as_they_are() -> None:
    with pytest.raises(PermissionError):
        _accept(_Choking(PermissionError(13, "denied")), None, "input")  # type: ignore[arg-type]


def test_an_unexpected_exception_is_a_json_500_and_the_connection_stays_usable() -> None:
    app = FastAPI()
    errors.install(app)
    app.add_middleware(errors.InternalErrors)

    @app.get("/boom")
    def boom() -> None:
        raise RuntimeError("bug")

    @app.get("/fine")
    def fine() -> dict[str, bool]:
        return {"ok": True}

    with TestClient(app, raise_server_exceptions=False) as c:
        r = c.get("/boom")
        assert r.status_code == 500 and r.headers["content-type"] == "application/json"
        assert json.loads(r.content)["detail"]["code"] == "internal_error"
        assert c.get("/fine").json() == {"ok": True}


def test_format_npz_on_an_artifact_that_is_not_a_ply_is_refused(client: TestClient) -> None:
    # A succeeded panel-axis job with its PNG overlay, made in the store as a worker would.
    service = client.app.state.service  # type: ignore[attr-defined]
    job = service.store.create(kind="panel-axis", options={}, input={}, owner=None)
    service.artifacts.save_bytes(job.id, "overlay.png", b"\x89PNG\r\n\x1a\n")
    service.store.claim(job.id)
    assert service.store.succeed(job.id, {}, {"overlay": "overlay.png"})
    d = detail(client.get(f"/v1/jobs/{job.id}/artifacts/overlay", params={"format": "npz"}))
    assert d["field"] == "format" and "PLY" in d["message"]
    assert detail(client.get(f"/v1/jobs/{job.id}/artifacts/report", params={"format": "npz"}))["field"] == "format"
    assert client.get(f"/v1/jobs/{job.id}/artifacts/overlay").status_code == 200
    # Each artifact says what to save it as: the CLI saved linescan's cloud as cloud.bin.
    listed = {a["name"]: a["filename"] for a in client.get(f"/v1/jobs/{job.id}/artifacts").json()}
    assert listed == {"overlay": "overlay.png", "report": "report.html"}
    d = detail(client.get(f"/v1/jobs/{job.id}/cloud"), 404)
    assert "panel-axis writes none" in d["message"]
