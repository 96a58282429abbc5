"""Estimates against seeded simulations' truth, the paper's chain beside ours, and the CLI."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tumblescan.cli.marker_pose import app
from tumblescan.marker_pose.estimate import estimate_poses
from tumblescan.marker_pose.evaluate import evaluate
from tumblescan.marker_pose.markers_io import markers_from_json
from tumblescan.marker_pose.options import MarkerPoseOptions
from tumblescan.marker_pose.simulate import SimConfig, simulate


@pytest.mark.parametrize(
    ("target", "motion", "seed"), [("kite", "paper", 0), ("box", "paper", 1), ("kite", "tumble", 1)]
)
def test_given_layout_is_efficient_and_covered(target: str, motion: str, seed: int) -> None:
    sim = simulate(SimConfig(target=target, motion=motion, frames=300), seed)
    result = estimate_poses(markers_from_json(sim.document()))
    ev = evaluate(result, sim.truth())
    assert ev["ratio"] <= 1.3
    assert ev["coverage"] >= 0.98
    assert 0.25 <= ev["nees_over_6"] <= 4
    assert abs(ev["drift_deg"]) < 0.5
    assert ev["unbounded_worst_sigma"] < 5  # a frame measured without 3 true inliers is still within its covariance


def test_layout_is_bootstrapped_when_none_is_given() -> None:
    sim = simulate(SimConfig(target="kite", frames=300, with_layout=False), 0)
    result = estimate_poses(markers_from_json(sim.document()))
    assert result.layout.source == "estimated"
    assert len(result.layout.markers) == 4
    ev = evaluate(result, sim.truth())
    assert ev["ratio"] <= 1.3
    assert ev["coverage"] >= 0.98


def test_constant_velocity_prior_smooths_below_the_per_frame_bound() -> None:
    sim = simulate(SimConfig(target="kite", frames=300), 2)
    data = markers_from_json(sim.document())
    result = estimate_poses(data, MarkerPoseOptions(motion_prior="constant_velocity"))
    ev = evaluate(result, sim.truth())
    assert ev["ratio"] < 0.6  # smoothing over frames beats the per-frame bound
    assert 0.25 <= ev["nees_over_6"] <= 4  # and the graph's covariances say so honestly
    assert ev["coverage"] >= 0.98
    assert result.graph.factors["motion"] > 250


def test_paper_chain_is_worse_than_ours() -> None:
    sim = simulate(SimConfig(target="kite", frames=300), 3)
    data = markers_from_json(sim.document())
    paper = evaluate(estimate_poses(data, MarkerPoseOptions(method="paper")), sim.truth())
    ours = evaluate(estimate_poses(data), sim.truth())
    assert ours["ratio"] < paper["ratio"]


def test_swapped_identities_are_caught() -> None:
    sim = simulate(SimConfig(target="box", frames=300, swaps=3, outlier_fraction=0.0), 4)
    result = estimate_poses(markers_from_json(sim.document()))
    truth = sim.truth()["tracks"]
    # Every track's majority association is its true marker (the swapped tracks end on another one).
    wrong = [tr for tr, m in result.associations.items() if m is not None and truth[tr] is not None and m != truth[tr]]
    assert len(wrong) <= 2 * 3  # only the swapped tracks (two per swap) may end on another marker


def test_cli_estimate_prints_one_json_document(tmp_path: Path) -> None:
    runner = CliRunner()
    assert runner.invoke(app, ["simulate", "--out", str(tmp_path), "--seed", "5", "--frames", "100"]).exit_code == 0
    r = runner.invoke(app, ["estimate", str(tmp_path / "markers.json"), "--json", "--report", str(tmp_path / "r.html")])
    assert r.exit_code == 0
    doc = json.loads(r.stdout)
    assert doc["kind"] == "marker-pose-graph" and len(doc["poses"]) > 90
    assert (tmp_path / "r.html").read_text().startswith("<!DOCTYPE html>")


def test_cli_bad_input_exits_2_with_one_line(tmp_path: Path) -> None:
    sim = simulate(SimConfig(frames=50), 0)
    doc = sim.document()
    doc["units"]["length"] = "mm"
    (tmp_path / "m.json").write_text(json.dumps(doc))
    r = CliRunner().invoke(app, ["estimate", str(tmp_path / "m.json"), "--json"])
    assert r.exit_code == 2
    assert "units.length" in r.output


def test_client_model_reads_the_result() -> None:
    from tumblescan_client.results import result_model

    sim = simulate(SimConfig(frames=60), 8)
    result = estimate_poses(markers_from_json(sim.document()), MarkerPoseOptions(motion_prior="constant_velocity"))
    typed = result_model("marker-pose-graph").model_validate_json(result.model_dump_json())
    assert typed.model_dump(mode="json") == result.model_dump(mode="json")


def test_report_has_trajectory_attitude_and_residuals() -> None:
    from tumblescan.marker_pose.report import build_report

    sim = simulate(SimConfig(frames=60), 9)
    html = build_report(estimate_poses(markers_from_json(sim.document())), "t")
    for div in ("trajectory", "attitude", "position", "Residuals per marker"):
        assert div in html


@pytest.mark.parametrize(
    "opts", [{"robust": "huber"}, {"body_frame": "launch"}, {"robust": "cauchy", "marginals": True}]
)
def test_options_keep_the_estimate_efficient(opts: dict[str, str]) -> None:
    sim = simulate(SimConfig(target="kite", frames=200), 10)
    result = estimate_poses(markers_from_json(sim.document()), MarkerPoseOptions.model_validate(opts))
    ev = evaluate(result, sim.truth())
    assert ev["ratio"] <= 1.3 and ev["coverage"] >= 0.98
    assert result.body_frame == opts.get("body_frame", "layout")


def test_layout_body_frame_without_a_layout_is_refused() -> None:
    from tumblescan.errors import InputError

    sim = simulate(SimConfig(frames=60, with_layout=False), 0)
    with pytest.raises(InputError) as err:
        estimate_poses(markers_from_json(sim.document()), MarkerPoseOptions(body_frame="layout"))
    assert err.value.code == "invalid_option" and err.value.field == "body_frame"
