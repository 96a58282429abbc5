"""``tumblescan submit``: what can only fail after the job has run is refused before it is
submitted, in one line with exit code 2."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from typer.testing import CliRunner

import tumblescan_client
from tumblescan.cli import app

runner = CliRunner()


@pytest.fixture
def service(api: TestClient) -> TestClient:
    return api


@pytest.fixture
def to_service(service: TestClient, monkeypatch: pytest.MonkeyPatch) -> None:
    real = tumblescan_client.Client

    def client(url: str | None = None, **kw: Any) -> tumblescan_client.Client:
        return real("http://testserver", transport=service._transport, **kw)

    monkeypatch.setattr(tumblescan_client, "Client", client)


def submit(*args: str) -> Any:
    return runner.invoke(app, ["submit", *args, "--url", "http://127.0.0.1:9"])


def one_error_line(r: Any, words: str) -> None:
    assert r.exit_code == 2, r.output
    assert r.output.count("\n") == 1 and words in r.output, r.output


def test_outputs_that_could_only_fail_later_are_refused_first(tmp_path: Path) -> None:
    # Port 9 has no service: each refusal comes before the client is used.
    f = tmp_path / "tracks.json"
    f.write_text("{}")
    for timeout in ("0", "nan", "inf"):
        one_error_line(submit(str(f), "--wait", "--timeout", timeout), "--timeout must be a finite number of seconds")
    one_error_line(submit(str(f), "--out", str(tmp_path / "x.ply")), "--out needs --wait")
    one_error_line(submit(str(f), "--artifacts", str(tmp_path / "a")), "--artifacts needs --wait")
    one_error_line(submit(str(f), "--wait", "--out", str(tmp_path)), "is a directory")
    one_error_line(submit(str(f), "--wait", "--out", str(tmp_path / "no" / "x.ply")), "no such directory")
    one_error_line(submit(str(f), "--wait", "--artifacts", str(f)), "exists and is not a directory")


def test_a_directory_given_as_a_file_is_named_a_directory(tmp_path: Path, to_service: None) -> None:
    one_error_line(submit("--kind", "bearings", str(tmp_path)), "is a directory")


def test_out_for_a_kind_without_a_cloud_is_refused_before_submitting(
    tmp_path: Path, to_service: None, service: TestClient
) -> None:
    f = tmp_path / "input.json"
    f.write_text("{}")
    before = service.get("/v1/jobs").json()["items"]
    r = submit("--kind", "bearings", str(f), "--wait", "--out", str(tmp_path / "x.ply"))
    one_error_line(r, "bearings has none; use --artifacts DIR")
    assert service.get("/v1/jobs").json()["items"] == before


def test_a_service_url_without_a_scheme_is_one_line(tmp_path: Path) -> None:
    f = tmp_path / "tracks.json"
    f.write_text("{}")
    one_error_line(runner.invoke(app, ["submit", str(f), "--url", "localhost:8000"]), "must start with http://")
    one_error_line(runner.invoke(app, ["report", "abc", "--url", "localhost:8000"]), "must start with http://")


@pytest.mark.parametrize(
    ("options", "words"),
    [
        ("[" * 100_000 + "]" * 100_000, "--options: the JSON nests too deeply"),
        ("{x", "--options: not valid JSON"),
        ("[1]", "--options must be a JSON object"),
    ],
)
def test_options_that_are_not_a_json_object_are_one_line(tmp_path: Path, options: str, words: str) -> None:
    f = tmp_path / "input.json"
    f.write_text("{}")
    r = submit("--kind", "bearings", "--options", options, f"input={f}")
    assert r.exit_code == 2 and r.output.count("\n") == 1 and words in r.output, r.output


def test_a_bare_zip_goes_to_the_kinds_archive_part(tmp_path: Path, to_service: None) -> None:
    # Refused for its content, as the archive: it went to the part that takes zips, not to
    # 'meta' (the kind's first part), which would have been refused for want of frames.
    f = tmp_path / "sequence.zip"
    f.write_bytes(b"not really a zip")
    r = submit("--kind", "spin-from-images", str(f))
    assert r.exit_code == 2 and "archive" in r.output and "needs 'frames'" not in r.output, r.output


def test_bare_tracks_json_goes_to_the_file_part_of_linescan(tmp_path: Path, to_service: None) -> None:
    # The README's own command: linescan's 'file' takes tracks (JSON, CSV) in one form and frames
    # (PLY, NPZ) in the other; a bare tracks.json once went to 'truth', the next part taking JSON.
    from tumblescan import tracks_to_json

    from ..conftest import tracks_for

    f = tmp_path / "tracks.json"
    f.write_text(json.dumps(tracks_to_json(tracks_for(1)[1])))
    r = submit(str(f))
    assert r.exit_code == 0, r.output
    assert json.loads(r.output)["status"] == "queued"


def test_an_unknown_part_is_named_as_such(tmp_path: Path, to_service: None) -> None:
    f = tmp_path / "frames.ply"
    f.write_text("ply")
    # It said "no such file: bogus=...", as if the part's name were part of the path.
    one_error_line(submit(f"bogus={f}"), "unknown part 'bogus'")


def test_report_checks_its_output_before_the_download(tmp_path: Path) -> None:
    # Port 9 has no service: refused before the client is used (it downloaded megabytes first).
    report = ["report", "abc", "--url", "http://127.0.0.1:9", "--out"]
    one_error_line(runner.invoke(app, [*report, str(tmp_path / "no" / "r.html")]), "no such directory")
    one_error_line(runner.invoke(app, [*report, str(tmp_path)]), "is a directory")


def test_a_bad_api_key_is_the_callers_mistake_exit_2(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from fastapi.testclient import TestClient as Service

    from tumblescan.api.app import create_app
    from tumblescan.settings import Settings

    settings = Settings(data_dir=tmp_path / "data", api_keys=["right"])
    with Service(create_app(settings)) as service:
        real, transport = tumblescan_client.Client, service._transport
        monkeypatch.setattr(
            tumblescan_client, "Client", lambda url=None, **kw: real("http://testserver", transport=transport, **kw)
        )
        f = tmp_path / "input.json"
        f.write_text("{}")
        r = runner.invoke(app, ["submit", "--kind", "bearings", str(f), "--api-key", "wrong"])
    assert r.exit_code == 2, r.output
    assert r.output.startswith("error: 401") and r.output.count("\n") == 1, r.output


def test_a_wait_that_times_out_says_so_on_a_line_of_its_own(tmp_path: Path, to_service: None) -> None:
    # No workers: the job stays queued, the bar is drawn, and the timeout's error follows it.
    from tumblescan import tracks_to_json

    from ..conftest import tracks_for

    f = tmp_path / "tracks.json"
    f.write_text(json.dumps(tracks_to_json(tracks_for(1)[1])))
    r = submit(str(f), "--wait", "--timeout", "0.5")
    assert r.exit_code != 0
    last = r.output.rstrip("\n").split("\n")[-1]
    assert last.startswith("error: ") and "[" not in last, r.output
