"""The CLI as a user runs it: a real subprocess, exit codes, stdout and stderr."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tumblescan import MotionResult, read_ply
from tumblescan.linescan.truth import errors_against, motion_from_json


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "tumblescan", *args], capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def sim(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("sim")
    proc = run("simulate", "--out", str(out), "--seed", "4", "--lines", "96", "--pixels", "96")
    assert proc.returncode == 0, proc.stderr
    return out


def test_simulate_writes_tracks_frames_and_truth(sim: Path) -> None:
    for name in ("tracks.json", "frames.ply", "reference.ply", "truth.json"):
        assert (sim / name).stat().st_size > 0
    cloud = read_ply(sim / "frames.ply")
    assert {"frame", "line", "pixel"} <= set(cloud.fields)
    assert cloud.fields["frame"].max() == 14


def test_estimate_json_prints_only_the_result_and_matches_the_truth(sim: Path) -> None:
    proc = run("estimate", str(sim / "tracks.json"), "--json")
    assert proc.returncode == 0, proc.stderr
    result = MotionResult.model_validate_json(proc.stdout)
    truth = motion_from_json(json.loads((sim / "truth.json").read_text())["motion"])
    err = errors_against(result, truth)
    assert abs(err["spin_rate_deg_s"]) < 5 * result.uncertainty.spin_rate_deg_s
    assert abs(err["spin_axis_deg"]) < 5 * result.uncertainty.spin_axis_deg


def test_estimate_prints_a_readable_summary(sim: Path) -> None:
    proc = run("estimate", str(sim / "tracks.json"), "--strategy", "swarm", "--seed", "3")
    assert proc.returncode == 0, proc.stderr
    assert "spin rate" in proc.stdout and "swarm(naiwpso)+lm" in proc.stdout


def test_rectify_writes_a_cloud_near_the_truth(sim: Path, tmp_path: Path) -> None:
    result = run("estimate", str(sim / "tracks.json"), "--json", "--reference-time-s", "0")
    (tmp_path / "r.json").write_text(result.stdout)
    proc = run(
        "rectify", str(sim / "frames.ply"), "--motion", str(tmp_path / "r.json"), "--out", str(tmp_path / "out.ply")
    )
    assert proc.returncode == 0, proc.stderr
    rect, ref = read_ply(tmp_path / "out.ply"), read_ply(sim / "reference.ply")
    # Sensor noise (2 cm) stays in the cloud; the distortion (metres) is gone.
    assert np.median(np.linalg.norm(rect.xyz_m - ref.xyz_m, axis=1)) < 0.1
    assert np.array_equal(rect.fields["line"], ref.fields["line"])


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ('{"observations": []}', "'observations' must be a non-empty list"),
        ('{"observations": [{"track": "a", "t": 0, "xyz": [1, 2]}]}', "observations[0].xyz"),
        ("track,t,x,y,z\na,0,1,2,3\n", "seen only once"),
    ],
)
def test_bad_input_exits_2_with_one_line_on_stderr(tmp_path: Path, content: str, message: str) -> None:
    path = tmp_path / ("bad.csv" if content.startswith("track") else "bad.json")
    path.write_text(content)
    proc = run("estimate", str(path))
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and message in proc.stderr
    assert "Traceback" not in proc.stderr


def test_missing_file_and_bad_motion_file_exit_2(tmp_path: Path, sim: Path) -> None:
    proc = run("estimate", str(tmp_path / "nope.json"))
    assert proc.returncode == 2 and "no such file" in proc.stderr
    (tmp_path / "m.json").write_text("{}")
    proc = run(
        "rectify", str(sim / "frames.ply"), "--motion", str(tmp_path / "m.json"), "--out", str(tmp_path / "o.ply")
    )
    assert proc.returncode == 2 and "not a motion result" in proc.stderr
