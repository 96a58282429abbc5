"""The marker-pose-graph CLI: a flag of another level or method refused in one line (exit 2, the
API's words), nothing simulated for a flag of another level, a false zip named as such, and a
summary that gives the estimate with its 1-sigma."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from tumblescan.cli.marker_pose import app

runner = CliRunner()


@pytest.fixture(scope="module")
def sims(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    out = tmp_path_factory.mktemp("cli")
    r = runner.invoke(app, ["simulate", "--out", str(out / "m1"), "--seed", "0", "--frames", "100"])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["simulate", "--out", str(out / "m2"), "--level", "B", "--frames", "20"])
    assert r.exit_code == 0, r.output
    return {"A": out / "m1" / "markers.json", "B": out / "m2" / "tags.json", "dir": out}


def _one_line_refusal(args: list[str]) -> str:
    r = runner.invoke(app, args)
    assert r.exit_code == 2, r.output
    lines = r.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), r.output
    return lines[0]


@pytest.mark.parametrize(
    ("level", "flags", "named"),
    [
        ("B", ["--detector", "aruco"], "--detector: does not apply to tags input"),
        ("A", ["--pixel-sigma-px", "0.3"], "--pixel-sigma-px: does not apply to markers input"),
        ("A", ["--detector", "aruco"], "--detector: does not apply to markers input"),
        ("A", ["--detector", "apriltag"], "--detector: does not apply to markers input"),  # the default, given
        ("B", ["--method", "graph"], "--method: does not apply to tags input"),
    ],
)
def test_a_flag_of_another_level_is_refused(sims: dict[str, Path], level: str, flags: list[str], named: str) -> None:
    assert named in _one_line_refusal(["estimate", str(sims[level]), *flags])


def test_paper_method_with_a_motion_prior_is_refused(sims: dict[str, Path]) -> None:
    # The paper's graph has only between factors: the result claimed constant_velocity while
    # bridging nothing.
    args = ["estimate", str(sims["A"]), "--method", "paper", "--motion-prior", "constant_velocity", "--json"]
    line = _one_line_refusal(args)
    assert "motion_prior" in line and "method 'paper'" in line


@pytest.mark.parametrize(
    ("flags", "named"),
    [
        (["--level", "B", "--target", "kite"], "--target"),
        (["--level", "B", "--target", "box"], "--target"),
        (["--level", "B", "--no-layout"], "--layout/--no-layout"),
        (["--level", "C", "--layout"], "--layout/--no-layout"),
        (["--frames", "5"], "frames"),  # level A simulates 10 or more; 5 became 10 silently
    ],
)
def test_simulate_refuses_a_flag_of_another_level_and_writes_nothing(
    tmp_path: Path, flags: list[str], named: str
) -> None:
    assert named in _one_line_refusal(["simulate", "--out", str(tmp_path / "out"), *flags])
    assert not (tmp_path / "out").exists()


def test_a_false_zip_is_named_as_not_a_readable_zip(tmp_path: Path) -> None:
    (tmp_path / "bad.zip").write_text("not a zip")
    assert "images: not a readable zip" in _one_line_refusal(["estimate", str(tmp_path / "bad.zip")])


def test_report_in_a_missing_directory_is_refused_before_the_work(sims: dict[str, Path]) -> None:
    line = _one_line_refusal(["estimate", str(sims["A"]), "--report", str(sims["dir"] / "nowhere" / "r.html")])
    assert "--report" in line


def test_summary_gives_the_last_pose_with_its_sigma_near_the_truth(sims: dict[str, Path]) -> None:
    r = runner.invoke(app, ["estimate", str(sims["A"])])
    assert r.exit_code == 0, r.output
    m = re.search(
        r"last measured frame (\d+) \(t [\d.]+ s\): position \[([-\d., ]+)\] m \+- \[([\d., ]+)\] mm, "
        r"yaw/pitch/roll from launch \[[-\d., ]+\] deg \+- ([\d.]+) deg \(1 sigma\)",
        r.output,
    )
    assert m, r.output
    assert re.search(r"median 1-sigma over \d+ measured frames: [\d.]+ deg attitude, [\d.]+ mm position", r.output)
    frame = int(m.group(1))
    position = np.array([float(v) for v in m.group(2).split(",")])
    sigma_mm = np.array([float(v) for v in m.group(3).split(",")])
    truth = json.loads((sims["A"].parent / "truth.json").read_text())
    true_position = np.array(truth["frames"][frame]["t_m"])
    # Kite markers at 2.9 mm: about 1.5 mm per axis; the error within 4 sigma (and rounding).
    assert np.all((sigma_mm > 0.5) & (sigma_mm < 5))
    assert np.all(np.abs(position - true_position) * 1000 < 4 * sigma_mm + 0.1)
