"""``tumblescan bearings simulate | estimate`` through typer's runner."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from tumblescan.cli.bearings import app


def test_cli_simulate_writes_input_truth_and_invalid_copies(tmp_path: Path) -> None:
    res = CliRunner().invoke(
        app, ["simulate", "--out", str(tmp_path), "--seed", "4", "--scene", "close", "--targets", "4"]
    )
    assert res.exit_code == 0, res.output
    doc = json.loads((tmp_path / "input.json").read_text())
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert truth["targets"] == 4 and len(doc["frames"]) == 10
    assert len(list((tmp_path / "invalid").glob("*.json"))) > 20


def test_cli_simulate_refuses_an_unknown_scene(tmp_path: Path) -> None:
    res = CliRunner().invoke(app, ["simulate", "--out", str(tmp_path), "--scene", "moon"])
    assert res.exit_code == 2
    assert "--scene" in res.output


def test_cli_estimate_json_prints_one_document_and_writes_a_report(tmp_path: Path) -> None:
    runner = CliRunner()
    assert runner.invoke(app, ["simulate", "--out", str(tmp_path), "--scene", "paper", "--frames", "3"]).exit_code == 0
    report = tmp_path / "report.html"
    res = runner.invoke(app, ["estimate", str(tmp_path / "input.json"), "--json", "--report", str(report)])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)  # exactly one JSON document
    assert doc["status"] == "succeeded" and len(doc["frames"]) == 3
    assert doc["summary"]["targets"] == sum(len(f["targets"]) for f in doc["frames"])
    text = report.read_text()
    assert "bearings-3d" in text and "Unassociated" in text and "<h2>Tracks</h2>" in text
    # The close-up draws one line per track, named as in the result.
    assert doc["tracks"] and "bearings-close-up" in text
    assert all(f'"name":"{track["id"]}"' in text for track in doc["tracks"])


def test_cli_estimate_paper_method(tmp_path: Path) -> None:
    runner = CliRunner()
    runner.invoke(app, ["simulate", "--out", str(tmp_path), "--scene", "paper", "--frames", "4"])
    res = runner.invoke(app, ["estimate", str(tmp_path / "input.json"), "--json", "--method", "paper"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["summary"]["method"] == "paper"


def test_cli_estimate_bad_input_exits_2_with_the_failure_document(tmp_path: Path) -> None:
    runner = CliRunner()
    runner.invoke(app, ["simulate", "--out", str(tmp_path), "--scene", "paper", "--frames", "2"])
    bad = tmp_path / "invalid" / "el_above_90.json"
    res = runner.invoke(app, ["estimate", str(bad), "--json"])
    assert res.exit_code == 2
    doc = json.loads(res.stdout)
    assert doc["status"] == "failed" and doc["error"]["code"] == "invalid_input"
    assert ".el_deg = 95 is outside [-90, 90]" in doc["error"]["message"]
    assert res.stderr.count("\n") == 1 and res.stderr.startswith("error: frames[")
    res = runner.invoke(app, ["estimate", str(tmp_path / "missing.json")])
    assert res.exit_code == 2 and "no such file" in res.stderr
