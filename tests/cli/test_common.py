"""What every command shares (cli/common.py): bad input is exit code 2 and one line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tumblescan import tracks_to_json
from tumblescan.cli import app

from ..conftest import tracks_for

runner = CliRunner()


def test_json_nested_too_deeply_is_one_line_for_every_estimate(tmp_path: Path) -> None:
    # The readers of each kind call json.loads; the shared wrapper catches what they let through.
    deep = tmp_path / "deep.json"
    deep.write_text('{"observations": ' + "[" * 100_000 + "]" * 100_000 + "}")
    for group in ("linescan-motion", "marker-pose-graph", "bearings"):
        r = runner.invoke(app, [group, "estimate", str(deep)])
        assert r.exit_code == 2, r.output
        assert r.output.count("\n") == 1 and "nests too deeply" in r.output, r.output


def test_usage_errors_are_one_line_and_exit_2(tmp_path: Path) -> None:
    # click's usage box (5+ lines) for a bad flag value, an unknown option or command, a missing argument.
    f = tmp_path / "input.json"
    f.write_text("{}")
    cases = [
        (["bearings", "estimate", str(f), "--method", "zzz"], "--method: Input should be "),
        (["panel-axis", "estimate", str(f), "--seed", "-1"], "'--seed'"),
        (["kinds", "--zzz"], "No such option: --zzz"),
        (["no-such-command"], "No such command"),
        (["report"], "Missing argument"),
    ]
    for args, words in cases:
        r = runner.invoke(app, args)
        assert r.exit_code == 2, r.output
        assert r.output.count("\n") == 1 and r.output.startswith("error: ") and words in r.output, r.output
    assert runner.invoke(app, ["kinds"]).exit_code == 0
    assert runner.invoke(app, ["--help"]).exit_code == 0


def test_an_option_value_the_options_model_refuses_is_one_line(tmp_path: Path) -> None:
    f = tmp_path / "tracks.json"
    f.write_text(json.dumps(tracks_to_json(tracks_for(1)[1])))
    r = runner.invoke(app, ["linescan-motion", "estimate", str(f), "--range-sigma-m", "-1"])
    assert r.exit_code == 2 and r.output.count("\n") == 1, r.output
    assert "range_sigma_m" in r.output


def test_two_outputs_naming_one_file_are_refused_before_the_work(tmp_path: Path) -> None:
    from tumblescan.cli.common import check_output_files
    from tumblescan.errors import InputError

    f = tmp_path / "result.json"
    with pytest.raises(InputError, match="--out and --report are the same file"):
        check_output_files(out=f, report=tmp_path / "." / "result.json")
    check_output_files(out=f, report=tmp_path / "report.html", rectified=None)
    # spin-from-images wrote its result, then overwrote it with the report.
    r = runner.invoke(app, ["spin-from-images", "estimate", str(tmp_path), "--out", str(f), "--report", str(f)])
    assert r.exit_code == 2 and "the same file" in r.output and not f.exists(), r.output
