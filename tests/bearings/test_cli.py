"""``tumblescan bearings simulate | estimate`` through typer's runner."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
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


@pytest.fixture(scope="module")
def b1(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The review's ``b1``: ``tumblescan bearings simulate --out b1`` (paper scene, seed 0)."""
    out = tmp_path_factory.mktemp("b1")
    assert CliRunner().invoke(app, ["simulate", "--out", str(out)]).exit_code == 0
    return out


@pytest.mark.parametrize("value", ["0.1", "1000"])  # 16, the default, changes nothing and passes
def test_cli_refuses_the_gate_with_the_paper_method(b1: Path, value: str) -> None:
    args = ["estimate", str(b1 / "input.json"), "--method", "paper", "--gate-chi2", value]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 2
    assert res.stderr == "error: --gate-chi2: does not apply to method 'paper' (an option of method 'ml')\n"
    res = CliRunner().invoke(app, [*args, "--json"])
    assert res.exit_code == 2
    doc = json.loads(res.stdout)
    assert doc["status"] == "failed" and doc["error"]["code"] == "invalid_option"
    assert doc["error"]["field"] == "gate_chi2"


@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_cli_refuses_a_gate_that_is_not_finite(b1: Path, value: str) -> None:
    res = CliRunner().invoke(app, ["estimate", str(b1 / "input.json"), "--gate-chi2", value])
    assert res.exit_code == 2
    assert res.stderr == "error: --gate-chi2: Input should be a finite number\n"


def test_cli_gate_bounds_are_the_options_models(b1: Path) -> None:
    # The API takes any gate over 0: so does the CLI (its minimum was 0.1).
    res = CliRunner().invoke(app, ["estimate", str(b1 / "input.json"), "--gate-chi2", "0.05", "--json"])
    assert res.exit_code == 0, res.output
    for value, message in (("0", "greater than 0"), ("1000.5", "less than or equal to 1000")):
        res = CliRunner().invoke(app, ["estimate", str(b1 / "input.json"), "--gate-chi2", value])
        assert res.exit_code == 2 and res.stderr.startswith("error: --gate-chi2: ") and message in res.stderr


def test_cli_refuses_an_unknown_method_naming_it_with_the_failure_document(b1: Path) -> None:
    res = CliRunner().invoke(app, ["estimate", str(b1 / "input.json"), "--method", "best", "--json"])
    assert res.exit_code == 2 and res.stderr.startswith("error: --method: ")
    assert json.loads(res.stdout)["error"]["field"] == "method"


@pytest.mark.parametrize("option", ["--out", "--report"])
def test_cli_refuses_an_output_in_a_missing_directory_before_the_work(b1: Path, tmp_path: Path, option: str) -> None:
    missing = tmp_path / "nonexist" / "dir"
    res = CliRunner().invoke(app, ["estimate", str(b1 / "input.json"), option, str(missing / "r.json")])
    assert res.exit_code == 2
    assert res.stderr == f"error: {option}: the directory {missing} does not exist\n"
    assert not (tmp_path / "nonexist").exists()


def test_cli_refuses_out_and_report_on_one_file(b1: Path, tmp_path: Path) -> None:
    path = tmp_path / "r.json"
    res = CliRunner().invoke(app, ["estimate", str(b1 / "input.json"), "--out", str(path), "--report", str(path)])
    assert res.exit_code == 2 and not path.exists()
    assert res.stderr.startswith("error: --out and --report are the same file")


def test_cli_writes_no_result_when_the_report_fails(b1: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import errno

    import tumblescan.bearings.report

    def full_disk(*args: object, **kwargs: object) -> str:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(tumblescan.bearings.report, "build_report", full_disk)
    out, report = tmp_path / "r.json", tmp_path / "r.html"
    res = CliRunner().invoke(app, ["estimate", str(b1 / "input.json"), "--out", str(out), "--report", str(report)])
    assert res.exit_code == 2 and res.stderr.count("\n") == 1, res.output
    assert list(tmp_path.iterdir()) == []  # neither output, nor a temporary file


def test_cli_writes_both_outputs(b1: Path, tmp_path: Path) -> None:
    out, report = tmp_path / "r.json", tmp_path / "r.html"
    res = CliRunner().invoke(app, ["estimate", str(b1 / "input.json"), "--out", str(out), "--report", str(report)])
    assert res.exit_code == 0, res.output
    assert json.loads(out.read_text())["status"] == "succeeded" and "bearings-3d" in report.read_text()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.html", "r.json"]


@pytest.mark.parametrize("what", ["directory", "missing"])
def test_cli_json_prints_the_failure_document_for_an_input_it_cannot_read(tmp_path: Path, what: str) -> None:
    path = tmp_path / "adir"
    if what == "directory":
        path.mkdir()
    res = CliRunner().invoke(app, ["estimate", str(path), "--json"])
    assert res.exit_code == 2 and res.stderr.count("\n") == 1
    doc = json.loads(res.stdout)
    assert doc["status"] == "failed" and doc["error"]["field"] == "input"
    assert doc["error"]["message"] in res.stderr


def test_cli_summary_counts_what_tracks_lists_and_shows_positions_with_sigma(b1: Path) -> None:
    runner = CliRunner()
    doc = json.loads(runner.invoke(app, ["estimate", str(b1 / "input.json"), "--json"]).stdout)
    s = doc["summary"]
    ids = {t["track"] for fr in doc["frames"] for t in fr["targets"]}
    assert s["tracks"] == len(doc["tracks"]) and s["short_tracks"] == len(ids) - len(doc["tracks"]) > 0
    assert {tr["id"] for tr in doc["tracks"]} <= ids
    text = runner.invoke(app, ["estimate", str(b1 / "input.json")]).stdout
    lines = text.splitlines()
    assert f"{s['tracks']} tracks (+{s['short_tracks']} too short to fit)" in lines[0]
    first = doc["tracks"][0]
    row = next(line for line in lines if line.strip().startswith(first["id"] + ":"))
    assert f"{first['position_m'][0]:.2f}" in row and " ± (" in row  # sigma ~0.1-0.3 m: 2 decimals
    assert len(lines) == 2 + len(doc["tracks"])


def test_cli_summary_of_one_target_in_one_frame_is_singular(tmp_path: Path) -> None:
    runner = CliRunner()
    args = ["simulate", "--out", str(tmp_path), "--scene", "paper", "--targets", "1", "--frames", "1"]
    assert runner.invoke(app, args).exit_code == 0
    res = runner.invoke(app, ["estimate", str(tmp_path / "input.json")])
    assert res.exit_code == 0, res.output
    first, *rest = res.stdout.splitlines()
    assert first.startswith("1 target in 1 frame (0 ambiguous, 0 tracks (+1 too short to fit));")
    assert rest[0].startswith("frame 0 (t = ") and rest[1].startswith("  F0T0: (")


def test_cli_summary_lists_the_first_ten_and_counts_the_rest(tmp_path: Path) -> None:
    runner = CliRunner()
    args = ["simulate", "--out", str(tmp_path), "--scene", "swarm", "--targets", "14", "--frames", "1"]
    assert runner.invoke(app, args).exit_code == 0
    res = runner.invoke(app, ["estimate", str(tmp_path / "input.json"), "--no-tracks"])
    assert res.exit_code == 0, res.output
    lines = res.stdout.splitlines()
    n = int(lines[0].split()[0])
    assert len(lines) == 2 + 10 + 1 and lines[-1] == f"  ... and {n - 10} more (all in --json, --out and --report)"


def test_report_summary_counts_the_tracks_its_table_lists(b1: Path, tmp_path: Path) -> None:
    report = tmp_path / "r.html"
    res = CliRunner().invoke(app, ["estimate", str(b1 / "input.json"), "--json", "--report", str(report)])
    doc, text = json.loads(res.stdout), report.read_text()
    n, short = doc["summary"]["tracks"], doc["summary"]["short_tracks"]
    assert f"<td>tracks (fitted, listed below)</td><td>{n}</td>" in text
    assert f"<td>tracks too short to fit (under 3 fixes)</td><td>{short}</td>" in text
    tracks_table = text.split("<h2>Tracks</h2>")[1].split("<h2>")[0]
    assert tracks_table.count("<tr>") - 1 == n == len(doc["tracks"])
