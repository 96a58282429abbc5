"""``tumblescan panel-axis simulate | estimate``: files written, one JSON document, exit 2 on bad input."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from typer.testing import CliRunner, Result

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


def _one_error_line(r: Result) -> str:
    assert r.exit_code == 2, r.output
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    assert r.stdout == ""
    return lines[0]


def _no_prior(d: Path, tmp_path: Path) -> Path:
    meta = json.loads((d / "meta.json").read_text())
    del meta["prior"]
    meta["image"] = str(d / meta["image"])
    (tmp_path / "meta_noprior.json").write_text(json.dumps(meta))
    return tmp_path / "meta_noprior.json"


def test_require_axis_with_the_paper_method_is_refused(ground: Path, tmp_path: Path) -> None:
    # It answered the line of sight ("regime: perspective") with exit 0 on a weak-perspective view
    # without a prior, which --require-axis refuses with the default method.
    meta = _no_prior(ground, tmp_path)
    r = runner.invoke(app, ["estimate", str(meta), "--require-axis"])
    assert "error: prior: weak perspective" in _one_error_line(r)
    line = _one_error_line(runner.invoke(app, ["estimate", str(meta), "--require-axis", "--method", "paper"]))
    assert line.startswith("error: --require-axis: does not apply to method 'paper'"), line


def test_truth_without_report_is_refused(near_clean: Path) -> None:
    r = runner.invoke(app, ["estimate", str(near_clean / "meta.json"), "--truth", str(near_clean / "truth.json")])
    assert _one_error_line(r) == "error: --truth goes with --report (the truth is shown in the HTML report only)"


def test_outputs_are_checked_before_the_work(near_clean: Path, tmp_path: Path) -> None:
    # result.json was written, then the report failed ("no such file"); a missing --out directory
    # was named by its temporary file.
    ok = tmp_path / "ok.json"
    missing = tmp_path / "nonexist" / "r.html"
    r = runner.invoke(app, ["estimate", str(near_clean / "meta.json"), "--out", str(ok), "--report", str(missing)])
    assert _one_error_line(r) == f"error: --report: the directory {missing.parent} does not exist"
    assert not ok.exists()
    r = runner.invoke(app, ["estimate", str(near_clean / "meta.json"), "--out", str(tmp_path / "nonexist" / "r.json")])
    line = _one_error_line(r)
    assert line.startswith("error: --out: the directory") and ".tmp" not in line
    r = runner.invoke(app, ["estimate", str(near_clean / "meta.json"), "--out", str(ok), "--report", str(ok)])
    assert "--out and --report are the same file" in _one_error_line(r) and not ok.exists()


def test_a_directory_is_called_one(near_clean: Path) -> None:
    line = _one_error_line(runner.invoke(app, ["estimate", str(near_clean)]))
    assert line == f"error: meta: {near_clean} is a directory, not a file (did you mean {near_clean / 'meta.json'}?)"
    r = runner.invoke(app, ["estimate", str(near_clean / "meta.json"), "--image", str(near_clean)])
    assert _one_error_line(r) == f"error: image: {near_clean} is a directory, not a file"


def test_human_output_gives_each_value_with_its_sigma_rounded(near_clean: Path) -> None:
    r = runner.invoke(app, ["estimate", str(near_clean / "meta.json")])
    assert r.exit_code == 0, r.output
    doc = json.loads(runner.invoke(app, ["estimate", str(near_clean / "meta.json"), "--json"]).stdout)
    lines = r.stdout.splitlines()
    angle = next(x for x in lines if x.startswith("in-image angle: "))
    value, sigma = re.fullmatch(r"in-image angle: ([\d.]+) ± ([\d.]+) deg", angle).groups()  # type: ignore[union-attr]
    assert abs(float(value) - doc["image_angle_deg"]) <= 10 ** -len(value.split(".")[1])
    assert float(sigma) == pytest.approx(doc["sigma_image_angle_deg"], rel=0.05)
    pitch = next(x for x in lines if x.startswith("axis pitch "))
    assert re.fullmatch(r"axis pitch -?[\d.]+ ± [\d.]+ deg, yaw -?[\d.]+ ± [\d.]+ deg", pitch), pitch
    assert next(x for x in lines if x.startswith("tilt out of the image plane: ")).count("±") == 1
    assert not re.search(r"\d\.\d{7}", r.stdout), r.stdout  # no unrounded floats
    assert "None" not in r.stdout


def test_human_output_of_the_paper_method_says_what_it_does_not_give(ground: Path, tmp_path: Path) -> None:
    # It printed "sigma None deg", "perspective SNR None" and "regime: perspective" on a
    # weak-perspective image.
    report = tmp_path / "r.html"
    r = runner.invoke(app, ["estimate", str(ground / "meta.json"), "--method", "paper", "--report", str(report)])
    assert r.exit_code == 0, r.output
    assert "None" not in r.stdout and "regime: perspective" not in r.stdout, r.stdout
    assert r.stdout.startswith("regime: n/a (paper method")
    assert "axis (camera): [" in r.stdout and "sigma n/a (paper method)" in r.stdout
    assert "n/a (paper method)" in report.read_text()


def test_an_ambiguous_view_prints_the_mirror_twin(ground: Path) -> None:
    doc = json.loads(runner.invoke(app, ["estimate", str(ground / "meta.json"), "--json"]).stdout)
    assert doc["ambiguous"] and [c["kind"] for c in doc["candidates"]] == ["primary", "mirror"]
    mirror = doc["candidates"][1]
    assert mirror["sigma_pitch_deg"] > 0 and mirror["pitch_deg"] is not None
    r = runner.invoke(app, ["estimate", str(ground / "meta.json")])
    assert r.exit_code == 0, r.output
    twin = next(x for x in r.stdout.splitlines() if x.startswith("mirror twin (camera): "))
    printed = [float(x) for x in re.search(r"\[(.*)\]", twin).group(1).split(",")]  # type: ignore[union-attr]
    assert printed == pytest.approx(mirror["camera"], abs=1e-6)
    assert "mirror twin pitch " in r.stdout
