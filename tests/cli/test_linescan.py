"""The CLI as a user runs it: a real subprocess, exit codes, stdout and stderr."""

from __future__ import annotations

import json
import subprocess
import sys
from collections import Counter
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


def test_the_summary_states_the_centres_sigmas_in_millimetres(sim: Path) -> None:
    from tumblescan.cli.linescan import format_result

    proc = run("estimate", str(sim / "tracks.json"), "--json")
    result = MotionResult.model_validate_json(proc.stdout)
    # A sub-millimetre sigma must not print as 0.000 m.
    sigma_m = [0.00042, 0.0013, 0.000087]
    shown = format_result(result.model_copy(update={"uncertainty": result.uncertainty.model_copy(
        update={"center_m": sigma_m})})).splitlines()  # fmt: skip
    centre = next(line for line in shown if line.startswith("centre"))
    assert centre.endswith("+- [0.42, 1.3, 0.087] mm")


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


def test_the_kind_group_and_the_top_level_alias_agree(sim: Path) -> None:
    grouped = run("linescan-motion", "estimate", str(sim / "tracks.json"), "--json", "--seed", "2")
    alias = run("estimate", str(sim / "tracks.json"), "--json", "--seed", "2")
    assert grouped.returncode == alias.returncode == 0, grouped.stderr + alias.stderr
    a, b = MotionResult.model_validate_json(grouped.stdout), MotionResult.model_validate_json(alias.stdout)
    assert a.spin.rate_deg_s == b.spin.rate_deg_s and a.precession.center_m == b.precession.center_m


def test_a_tracks_option_with_frames_exits_2_naming_it(sim: Path) -> None:
    proc = run("linescan-motion", "estimate", str(sim / "frames.ply"), "--strategy", "lm")
    assert proc.returncode == 2 and proc.stderr == "error: --strategy applies to tracks input, not to frames\n"


def test_a_file_named_ply_that_is_not_one_says_so(tmp_path: Path) -> None:
    path = tmp_path / "scan.ply"
    path.write_bytes(bytes(range(256)) * 4)
    proc = run("estimate", str(path))
    assert proc.returncode == 2
    assert proc.stderr == "error: scan.ply is named .ply but is not a PLY file (its first bytes say otherwise)\n"
    path.write_bytes(b"")
    proc = run("estimate", str(path))
    assert proc.returncode == 2 and proc.stderr == "error: scan.ply is empty (0 bytes)\n"


def test_strategy_lm_on_tracks_the_initializer_cannot_use_exits_2(sim: Path, tmp_path: Path) -> None:
    # Two corners seen in every frame, a third only in frames 0-2: two frame pairs share 3.
    doc = json.loads((sim / "tracks.json").read_text())
    counts = Counter(o["track"] for o in doc["observations"])
    ids = [t for t, _ in counts.most_common(3)]
    keep = [o for o in doc["observations"] if o["track"] in ids[:2] or (o["track"] == ids[2] and o["frame"] < 3)]
    (tmp_path / "sparse.json").write_text(json.dumps({**doc, "observations": keep}))
    proc = run("estimate", str(tmp_path / "sparse.json"), "--strategy", "lm")
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert "strategy 'lm' needs the closed-form start" in proc.stderr and "Traceback" not in proc.stderr


def test_kinds_lists_the_kinds_and_their_forms() -> None:
    proc = run("kinds")
    assert proc.returncode == 0 and proc.stdout.startswith("linescan-motion: ")
    listing = json.loads(run("kinds", "--json").stdout)
    forms = {f["name"]: f for f in listing[0]["forms"]}
    assert listing[0]["name"] == "linescan-motion" and forms["frames"]["parts"] == ["file", "truth"]


def test_json_output_keeps_library_chatter_off_stdout() -> None:
    # What C code and Python print while --json work runs goes to stderr; stdout is the JSON alone.
    code = (
        "import ctypes, json, os, sys\n"
        "from tumblescan.cli.common import json_stdout\n"
        "with json_stdout(True):\n"
        "    os.write(1, b'[Open3D WARNING] Too few correspondences\\n')\n"
        "    ctypes.CDLL(None).puts(b'chatter from C')\n"
        "    print('chatter from Python')\n"
        "sys.stdout.write(json.dumps({'ok': True}) + '\\n')\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout) == {"ok": True}
    assert "Too few correspondences" in proc.stderr and "chatter from C" in proc.stderr


def test_simulate_a_mesh_file_and_its_mistakes(tmp_path: Path) -> None:
    from tumblescan._open3d import load_open3d

    o3d = load_open3d()
    mesh = o3d.geometry.TriangleMesh.create_box(6.0, 2.0, 2.0)
    assert o3d.io.write_triangle_mesh(str(tmp_path / "target.obj"), mesh)
    out = tmp_path / "sim"
    args = ("linescan-motion", "simulate", "--out", str(out), "--lines", "48", "--pixels", "48", "--no-dense")
    proc = run(*args, "--mesh", str(tmp_path / "target.obj"), "--size-m", "12", "--range-m", "60")
    assert proc.returncode == 0, proc.stderr
    scene = json.loads((out / "truth.json").read_text())["scene"]
    assert scene["shape"]["kind"] == "mesh" and scene["shape"]["size_m"] == 12.0
    proc = run(*args, "--mesh", str(tmp_path / "target.obj"))
    assert proc.returncode == 2 and proc.stderr == "error: --mesh needs --size-m (its largest side in metres)\n"
    proc = run(*args, "--mesh", str(tmp_path / "none.obj"), "--size-m", "3")
    assert proc.returncode == 2 and proc.stderr == f"error: --mesh: no such file: {tmp_path / 'none.obj'}\n"


def one_line_refusal(proc: subprocess.CompletedProcess[str], says: str) -> None:
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.startswith("error: ") and proc.stderr.count("\n") == 1 and says in proc.stderr, proc.stderr


def test_simulate_refuses_a_target_it_cannot_scan_naming_the_option(tmp_path: Path) -> None:
    (tmp_path / "flat.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n0 0 0\n0 0 0\n3 0 1 2\n"
    )
    (tmp_path / "a-file").write_text("")
    out = tmp_path / "sim"
    small = ("linescan-motion", "simulate", "--out", str(out), "--lines", "32", "--pixels", "32", "--frames", "4")
    cases = [
        (("--spin-rate-deg-s", "nan"), "--spin-rate-deg-s must be a finite number"),
        (("--range-m", "inf"), "--range-m must be a finite number"),
        (("--range-m", "1000000"), "--range-m: 1e+06 m is beyond the scanner's maximum range (1000 m)"),
        (("--range-m", "1"), "sees too few of the target's corners at 1 m: check --size-m and --range-m"),
        (("--mesh", str(tmp_path / "flat.ply"), "--size-m", "5"), "every triangle has zero area"),
        (("--mesh", str(tmp_path), "--size-m", "5"), f"--mesh: {tmp_path} is a directory"),
    ]
    for extra, says in cases:
        one_line_refusal(run(*small, *extra), says)
    # Nothing is written for a target out of view.
    assert not out.exists()
    one_line_refusal(run(*small, "--out", str(tmp_path / "a-file")), "--out: ")


def test_estimate_refuses_options_that_would_do_nothing_before_the_work(sim: Path, tmp_path: Path) -> None:
    tracks, frames = str(sim / "tracks.json"), str(sim / "frames.ply")
    one_line_refusal(run("estimate", tracks, "--truth", str(sim / "truth.json")), "--truth goes with --report")
    one_line_refusal(run("estimate", tracks, "--rectified", str(tmp_path / "r.ply")), "--rectified goes with --cloud")
    one_line_refusal(
        run("estimate", tracks, "--report", str(tmp_path / "no" / "r.html")),
        f"--report: the directory {tmp_path / 'no'} does not exist",
    )
    # The frames carry their frame indices: a frame period would be ignored.
    one_line_refusal(run("estimate", frames, "--frame-period-s", "0.5"), "'frame' property")
    (tmp_path / "c.json").write_text("{}")
    one_line_refusal(run("estimate", tracks, "--cloud", str(tmp_path / "c.json")), "cloud c.json: not a PLY file")
    # A truth the report could not show is refused before the work, and before any output.
    doc = json.loads((sim / "truth.json").read_text())
    doc["motion"]["spin_axis"] = [0, 0, 0]
    (tmp_path / "truth.json").write_text(json.dumps(doc))
    (tmp_path / "frames.ply").write_bytes((sim / "frames.ply").read_bytes())
    args = ("estimate", str(tmp_path / "frames.ply"), "--report", str(tmp_path / "r.html"))
    one_line_refusal(run(*args, "--truth", str(tmp_path / "truth.json")), "motion.spin_axis is the zero vector")
    assert not (tmp_path / "frames-rectified.ply").exists()


def test_rectify_refuses_a_reference_time_far_from_the_cloud(sim: Path, tmp_path: Path) -> None:
    result = run("estimate", str(sim / "tracks.json"), "--json")
    assert result.returncode == 0, result.stderr
    (tmp_path / "m.json").write_text(result.stdout)
    args = ("rectify", str(sim / "frames.ply"), "--motion", str(tmp_path / "m.json"), "--out", str(tmp_path / "r.ply"))
    one_line_refusal(run(*args, "--reference-time-s", "nan"), "--reference-time-s must be a finite number")
    one_line_refusal(run(*args, "--reference-time-s", "1e300"), "--reference-time-s: 1e+300 s lies too far")
    assert not (tmp_path / "r.ply").exists()
