"""The report's frame strip shows the target, not the sky around it; its numbers (and the CLI's)
carry their σ, rounded, and what a method does not give is "n/a" or left out, never None."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from tumblescan.spin_rate.pipeline import load_input
from tumblescan.spin_rate.report import _target_box, build_report
from tumblescan.spin_rate.result import SpinResult
from tumblescan.spin_rate.text import summary_rows, with_sigma

from .test_cli import paper_like


def test_the_strip_crops_to_the_target_in_every_frame() -> None:
    rng = np.random.default_rng(0)
    frames = []
    for x in (100, 140, 180):  # the target moves right across three frames
        g = rng.normal(10.0, 1.0, (512, 512))
        g[200:260, x : x + 60] = 200.0
        frames.append(g)
    x0, y0, x1, y1 = _target_box(frames)
    assert x0 <= 100 and x1 >= 240 and y0 <= 200 and y1 >= 260  # every frame's target inside
    assert x1 - x0 == y1 - y0 and x1 - x0 < 300  # a square, much smaller than the frame


def test_a_blank_sequence_keeps_the_whole_frame() -> None:
    frames = [np.full((64, 80), 5.0)]
    assert _target_box(frames) == (0, 0, 80, 64)


def _spin_table(html: str) -> str:
    return html[html.index("<h2>Spin</h2>") : html.index("<h2>Frames")]


def test_the_reports_numbers_carry_their_sigma_and_no_none(los_seq: Path, los_result: SpinResult) -> None:
    # It showed "mirror twin None" and "rival rates (deg/s) None" with the default method.
    doc = los_result.to_json()
    doc["spin"] |= {"axis_candidates": [], "axis_ambiguous": False}  # no twin, no rival
    table = _spin_table(build_report(load_input(los_seq / "meta.json"), doc))
    assert "None" not in table and "mirror twin" not in table and "rival rates" not in table
    assert f"{doc['spin']['sigma_axis_deg']:.1f}"[:3] in table and table.count("±") >= 3  # rate, period, axis


def _near_plane(result: SpinResult) -> dict[str, Any]:
    """``result`` as a near-image-plane fit reports it: no sense, a mirror twin and a rival rate."""
    doc = result.to_json()
    s = doc["spin"]
    s["sense_about_los"] = None
    s["axis_candidates"] = [
        {"axis_camera": [-0.1, 0.2, 0.97], "kind": "mirror", "cost": 1.01, "rate_deg_s": None},
        {"axis_camera": [0.9, 0.1, 0.4], "kind": "rate", "cost": 1.2, "rate_deg_s": 12.3456},
    ]
    return doc


def test_the_summary_says_what_is_not_given_instead_of_none(los_result: SpinResult) -> None:
    rows = dict(summary_rows(_near_plane(los_result)))
    assert rows["sense about the line of sight"].startswith("n/a (")
    assert rows["mirror twin (fits as well)"].startswith("[-0.100, 0.200, 0.970]")
    assert rows["rival rates (not ruled out)"].endswith(" deg/s") and "12.3" in rows["rival rates (not ruled out)"]
    paper = summary_rows(paper_like(los_result).to_json())
    static = los_result.to_json()
    static["spin"] |= {"spinning": False, "rate_deg_s": 0.0, "period_s": None, "sigma_period_s": None,
                       "axis_camera": None, "sigma_axis_deg": None, "sense_about_los": None,
                       "axis_los_angle_deg": None, "projected_axis_angle_deg": None, "axis_candidates": []}  # fmt: skip
    static["quality"] |= {"model": "static"}
    for rows_ in (paper, summary_rows(static)):
        assert all("None" not in value for _, value in rows_), rows_
    assert dict(paper)["axis, sense"].startswith("n/a")
    assert dict(summary_rows(static))["rate"].startswith("not spinning")


def test_values_are_rounded_to_their_sigma() -> None:
    assert with_sigma(13.32104, 2.04937, "deg/s") == "13.3 ± 2.0 deg/s"
    assert with_sigma(14.591234, 0.021345, "deg/s") == "14.591 ± 0.021 deg/s"
    assert with_sigma(360.0, 120.0, "s") == "360 ± 120 s"
    assert with_sigma(1.5, 0.0, "s") == "1.5000 ± 0.0000 s"
