"""The CLI: simulate -> estimate (dir and zip), --json prints JSON alone, bad input exits 2 with one line,
outputs checked before the work, --out the same with or without --report, a summary without None."""

from __future__ import annotations

import json
import shutil
import zipfile
from pathlib import Path

import pytest
from typer.testing import CliRunner, Result

from tumblescan.cli.spin_rate import app
from tumblescan.spin_rate import pipeline
from tumblescan.spin_rate import report as report_mod
from tumblescan.spin_rate.estimate import Sequence
from tumblescan.spin_rate.result import SpinResult

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


def _one_line(r: Result) -> str:
    lines = [x for x in r.output.splitlines() if x.strip()]
    assert r.exit_code == 2 and len(lines) == 1 and lines[0].startswith("error: "), r.output
    return lines[0]


def _fake_estimate(monkeypatch: pytest.MonkeyPatch, result: SpinResult) -> None:
    """estimate_spin replaced by ``result``, its tracks as meta.json's options say (as the real
    one does): the CLI's own logic in milliseconds."""

    def fake(seq: Sequence, options: object = None, progress: object = None) -> SpinResult:
        return result if seq.meta.options.return_tracks else result.model_copy(update={"tracks": None})

    monkeypatch.setattr(pipeline, "estimate_spin", fake)


def test_simulate_refuses_broken_without_kind_broken_meta(tmp_path: Path) -> None:
    # It wrote a valid sequence and exited 0, --broken ignored.
    r = runner.invoke(app, ["simulate", "--out", str(tmp_path / "sx1"), "--broken", "swapped_times",
                            "--width-px", "128", "--frames", "6"])  # fmt: skip
    line = _one_line(r)
    assert "--broken" in line and "broken-meta" in line
    assert not (tmp_path / "sx1").exists()


@pytest.mark.parametrize(
    ("args", "option"),
    [
        (["--out", "{tmp}/ok.json", "--report", "{tmp}/missing/r.html"], "--report"),
        (["--out", "{tmp}/missing/r.json"], "--out"),
        (["--report", "{tmp}"], "--report"),
    ],
)
def test_outputs_are_checked_before_the_work(
    los_seq: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, args: list[str], option: str
) -> None:
    # A missing --report directory was found after the whole estimate, --out already written; a
    # missing --out directory was named by its hidden temporary file (.r.json.tmp).
    def no_work(*a: object, **k: object) -> None:
        raise AssertionError("the estimate ran")

    monkeypatch.setattr(pipeline, "estimate_spin", no_work)
    r = runner.invoke(app, ["estimate", str(los_seq), *(a.format(tmp=tmp_path) for a in args)])
    line = _one_line(r)
    assert line.startswith(f"error: {option}:") and ".tmp" not in line
    assert not (tmp_path / "ok.json").exists()


def test_out_does_not_depend_on_report(
    los_seq: Path, los_result: SpinResult, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # --report once put every track observation into --out (and --json) without --tracks.
    _fake_estimate(monkeypatch, los_result)
    drawn: list[dict[str, object]] = []

    def build_report(seq: Sequence, doc: dict[str, object]) -> str:
        drawn.append(doc)
        return "<html></html>"

    monkeypatch.setattr(report_mod, "build_report", build_report)

    def out_doc(*extra: str) -> dict[str, object]:
        out = tmp_path / "result.json"
        r = runner.invoke(app, ["estimate", str(los_seq), "--out", str(out), *extra])
        assert r.exit_code == 0, r.output
        doc: dict[str, object] = json.loads(out.read_text())
        return doc

    plain = out_doc()
    with_report = out_doc("--report", str(tmp_path / "r.html"))
    assert plain["tracks"] is None and with_report == plain
    assert drawn and drawn[-1]["tracks"]  # the report still draws the tracked lines
    assert out_doc("--report", str(tmp_path / "r.html"), "--tracks")["tracks"]
    r = runner.invoke(app, ["estimate", str(los_seq), "--json", "--report", str(tmp_path / "r.html")])
    assert r.exit_code == 0 and json.loads(r.stdout)["tracks"] is None
    # Without --tracks/--no-tracks meta.json's options decide; --no-tracks overrides them.
    seq2 = tmp_path / "seq2"
    shutil.copytree(los_seq, seq2)
    meta = json.loads((seq2 / "meta.json").read_text())
    meta["options"]["return_tracks"] = True
    (seq2 / "meta.json").write_text(json.dumps(meta))
    for extra, has_tracks in (([], True), (["--no-tracks"], False)):
        r = runner.invoke(app, ["estimate", str(seq2), "--json", *extra])
        assert r.exit_code == 0 and bool(json.loads(r.stdout)["tracks"]) is has_tracks, extra


def test_the_summary_prints_sigmas_and_never_none(
    los_seq: Path, los_result: SpinResult, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The axis was printed without its σ; the paper's method printed "axis (camera): None, None deg".
    _fake_estimate(monkeypatch, los_result)
    r = runner.invoke(app, ["estimate", str(los_seq)])
    assert r.exit_code == 0, r.output
    s = los_result.spin
    assert s.axis_camera is not None and s.sigma_axis_deg is not None
    axis = next(x for x in r.stdout.splitlines() if x.startswith("axis (camera):"))
    assert "±" in axis and f"{s.sigma_axis_deg:.1f}"[:3] in axis
    rate = next(x for x in r.stdout.splitlines() if x.startswith("rate:"))
    assert "±" in rate and len(rate) < 40  # rounded to the σ, not 6 decimals
    _fake_estimate(monkeypatch, paper_like(los_result))
    r = runner.invoke(app, ["estimate", str(los_seq), "--method", "paper"])
    assert r.exit_code == 0, r.output
    assert "None" not in r.stdout and "n/a" in r.stdout and "rate:" in r.stdout


def paper_like(result: SpinResult) -> SpinResult:
    """``result`` as the paper's method gives it: a rate and no axis, sense or fit rms."""
    spin = result.spin.model_copy(update={
        "axis_camera": None, "sigma_axis_deg": None, "sense_about_los": None, "axis_los_angle_deg": None,
        "projected_axis_angle_deg": None, "axis_candidates": [], "axis_ambiguous": False,
    })  # fmt: skip
    quality = result.quality.model_copy(update={"model": "paper", "fit_rms_px": None})
    return result.model_copy(update={"method": "paper", "spin": spin, "quality": quality, "tracks": None})
