"""The CLI: simulate -> estimate (dir and zip), --json prints JSON alone, bad input exits 2 with one line."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

from typer.testing import CliRunner

from tumblescan.cli.spin_rate import app

runner = CliRunner()


def test_estimate_a_zip_prints_json_alone(los_seq: Path, tmp_path: Path) -> None:
    archive = tmp_path / "seq.zip"
    with zipfile.ZipFile(archive, "w") as zf:
        for p in los_seq.rglob("*"):
            if p.is_file():
                zf.write(p, p.relative_to(los_seq))
    r = runner.invoke(app, ["estimate", str(archive), "--json", "--out", str(tmp_path / "result.json")])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["schema"] == "tumblescan.spin_from_images.result/1" and doc["spin"]["rate_deg_s"] > 0
    assert json.loads((tmp_path / "result.json").read_text())["spin"] == doc["spin"]


def test_estimate_writes_a_report(los_seq: Path, tmp_path: Path) -> None:
    r = runner.invoke(app, ["estimate", str(los_seq), "--report", str(tmp_path / "r.html")])
    assert r.exit_code == 0, r.output
    assert "rate:" in r.stdout
    html = (tmp_path / "r.html").read_text()
    assert "spin-from-images" in html and "data:image/png;base64" in html


def test_bad_input_exits_2_with_one_line(los_seq: Path, tmp_path: Path) -> None:
    meta = json.loads((los_seq / "meta.json").read_text())
    meta["frames"][3]["t_s"] = meta["frames"][1]["t_s"]
    (tmp_path / "meta.json").write_text(json.dumps(meta))
    r = runner.invoke(app, ["estimate", str(tmp_path / "meta.json")])
    assert r.exit_code == 2
    lines = [x for x in r.output.splitlines() if x.strip()]
    assert len(lines) == 1 and "frames.3.t_s" in lines[0]


def test_simulate_writes_a_broken_meta_on_request(tmp_path: Path) -> None:
    r = runner.invoke(app, ["simulate", "--out", str(tmp_path / "b"), "--kind", "broken-meta", "--broken", "nan_time",
                            "--width-px", "64", "--frames", "6"])  # fmt: skip
    assert r.exit_code == 0, r.output
    truth = json.loads((tmp_path / "b" / "truth.json").read_text())
    assert truth["broken"]["field"] == "frames.3.t_s"
    r = runner.invoke(app, ["estimate", str(tmp_path / "b")])
    assert r.exit_code == 2 and "frames.3.t_s" in r.output
