"""Every level-A refusal names its field and carries its code."""

from __future__ import annotations

import copy
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from tumblescan.errors import InputError
from tumblescan.marker_pose.markers_io import markers_from_json, read_markers
from tumblescan.marker_pose.options import MarkerPoseLimits
from tumblescan.marker_pose.simulate import SimConfig, simulate

from .edits import set_at

BASE = simulate(SimConfig(frames=40), 0).document()


CASES: list[tuple[str, Callable[[dict[str, Any]], object], str, str]] = [
    ("length unit", set_at(["units", "length"], "mm"), "unsupported_units", "units.length"),
    ("time unit", set_at(["units", "time"], "ms"), "unsupported_units", "units.time"),
    ("NaN", set_at(["observations", 3, "xyz"], [float("nan"), 0.0, 1.0]), "non_finite_value", "observations[3].xyz"),
    (
        "duplicate",
        lambda d: d["observations"].insert(1, copy.deepcopy(d["observations"][0])),
        "duplicate_observation",
        "observations[1]",
    ),
    ("time order", set_at(["observations", 10, "t"], -1.0), "time_out_of_order", "observations[10].t"),
    (
        "two markers",
        lambda d: d["body"].__setitem__("markers", d["body"]["markers"][:2]),
        "degenerate_layout",
        "body.markers",
    ),
    (
        "collinear",
        lambda d: [m.__setitem__("xyz", [0.1 * i, 0.0, 0.0]) for i, m in enumerate(d["body"]["markers"])],
        "degenerate_layout",
        "body.markers",
    ),
    (
        "mm layout",
        lambda d: [m.__setitem__("xyz", [v * 1000 for v in m["xyz"]]) for m in d["body"]["markers"]],
        "layout_scale",
        "body.markers",
    ),
    ("duplicate id", set_at(["body", "markers", 1, "id"], "M1"), "duplicate_marker_id", "body.markers[1].id"),
    ("sigma zero", set_at(["sensor", "point_sigma_m"], 0.0), "noise_out_of_range", "sensor.point_sigma_m"),
    ("sigma large", set_at(["sensor", "point_sigma_m"], 2.9), "noise_out_of_range", "sensor.point_sigma_m"),
    ("far point", set_at(["observations", 5, "xyz"], [410.0, -220.0, 1530.0]), "out_of_volume", "observations[5].xyz"),
    ("too little", lambda d: d.__setitem__("observations", d["observations"][:5]), "too_few_frames", "observations"),
    ("unknown field", set_at(["colour"], "red"), "unknown_field", "colour"),
    ("format", set_at(["format"], "other"), "malformed_input", "format"),
    # Past int64 it once ended as an OverflowError traceback in the CLI.
    ("frame past 2^53", set_at(["observations", 2, "frame"], 10**30), "malformed_input", "observations[2].frame"),
]


@pytest.mark.parametrize(("name", "change", "code", "field"), CASES, ids=[c[0] for c in CASES])
def test_refusal_names_the_field(name: str, change: Callable[[dict[str, Any]], object], code: str, field: str) -> None:
    doc = copy.deepcopy(BASE)
    change(doc)
    with pytest.raises(InputError) as err:
        markers_from_json(doc)
    assert err.value.code == code
    assert err.value.field == field


def test_limits_are_enforced() -> None:
    with pytest.raises(InputError) as err:
        markers_from_json(copy.deepcopy(BASE), limits=MarkerPoseLimits(max_observations=10))
    assert err.value.code == "limit_exceeded"
    assert err.value.field == "observations"


def test_missing_sigma_warns_and_assumes_3_mm() -> None:
    doc = copy.deepcopy(BASE)
    del doc["sensor"]
    data = markers_from_json(doc)
    assert data.point_sigma_m == 0.003
    assert any("point_sigma_m" in w for w in data.warnings)


def test_csv_round_trip(tmp_path: Path) -> None:
    lines = ["frame,t,track,x,y,z"] + [
        f"{o['frame']},{o['t']},{o['track']},{o['xyz'][0]},{o['xyz'][1]},{o['xyz'][2]}" for o in BASE["observations"]
    ]
    (tmp_path / "m.csv").write_text("\n".join(lines))
    (tmp_path / "layout.json").write_text(json.dumps(BASE["body"]))
    data = read_markers(tmp_path / "m.csv", layout_path=tmp_path / "layout.json")
    ref = markers_from_json(BASE)
    assert data.n_frames == ref.n_frames
    assert data.layout is not None and data.layout.ids == ref.layout.ids  # type: ignore[union-attr]
    assert abs(data.xyz_m - ref.xyz_m).max() < 1e-9


def test_garbage_file_is_refused_naming_the_part(tmp_path: Path) -> None:
    (tmp_path / "m.bin").write_bytes(b"\x00\x01garbage")
    with pytest.raises(InputError) as err:
        read_markers(tmp_path / "m.bin")
    assert err.value.code == "malformed_input" and err.value.field == "markers"


def test_json_nested_too_deeply_is_refused_naming_the_part(tmp_path: Path) -> None:
    path = tmp_path / "markers.json"
    path.write_text('{"a": ' * 100_000 + "1" + "}" * 100_000)
    with pytest.raises(InputError, match="nests too deeply") as err:
        read_markers(path)
    assert err.value.field == "markers"
