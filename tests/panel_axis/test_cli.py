"""``tumblescan panel-axis simulate | estimate``: files written, one JSON document, exit 2 on bad input."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from tumblescan.cli.panel_axis import app

runner = CliRunner()


def test_estimate_json_prints_exactly_one_document(near_noisy: Path, tmp_path: Path) -> None:
    report = tmp_path / "report.html"
    r = runner.invoke(
        app,
        [
            "estimate",
            str(near_noisy / "meta.json"),
            "--json",
            "--report",
            str(report),
            "--truth",
            str(near_noisy / "truth.json"),
        ],
    )
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["schema"] == "tumblescan.panel_axis.result/1" and doc["status"] == "succeeded"
    assert doc["axis"]["sigma_deg"] > 0
    page = report.read_text()
    assert page.startswith("<!DOCTYPE html>") and "data:image/png;base64" in page and "sigma_CRLB" in page


def test_estimate_finds_the_image_relative_to_meta_from_anywhere(near_clean: Path, monkeypatch: object) -> None:
    r = runner.invoke(app, ["estimate", str(near_clean / "meta.json"), "--method", "paper", "--json"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["method"] == "paper"


def test_simulate_then_broken_meta_exits_2_with_one_line(tmp_path: Path) -> None:
    r = runner.invoke(
        app,
        [
            "simulate",
            "--out",
            str(tmp_path),
            "--seed",
            "1",
            "--case",
            "broken-meta",
            "--width-px",
            "320",
            "--height-px",
            "240",
        ],
    )
    assert r.exit_code == 0, r.output
    assert {p.name for p in tmp_path.iterdir()} == {"image.png", "meta.json", "truth.json"}
    r = runner.invoke(app, ["estimate", str(tmp_path / "meta.json"), "--json"])
    assert r.exit_code == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: camera.fx_px")
    assert r.stdout == ""


def test_a_truth_file_that_is_not_one_exits_2_before_any_work(tmp_path: Path) -> None:
    # The truth is read first: a broken meta.json proves the estimate never started.
    (tmp_path / "meta.json").write_text("{}")
    for content, words in [("{}", "truth.axis_camera"), ('{"a": NaN', "truth: not valid JSON"), ("[1]", "JSON object")]:
        (tmp_path / "truth.json").write_text(content)
        args = ["estimate", str(tmp_path / "meta.json"), "--truth", str(tmp_path / "truth.json")]
        r = runner.invoke(app, [*args, "--report", str(tmp_path / "r.html")])
        assert r.exit_code == 2 and r.exception is not None and not isinstance(r.exception, KeyError), r.output
        assert words in r.output and r.output.count("\n") == 1, r.output
