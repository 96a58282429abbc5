"""Every invalid input is refused with ``invalid_input`` naming the field; nothing else fails."""

from __future__ import annotations

import copy
import json
from typing import Any

import numpy as np
import pytest

from tumblescan.bearings.errors import TooLargeError
from tumblescan.bearings.estimate import estimate
from tumblescan.bearings.inputs import Limits, load_json, parse_input
from tumblescan.bearings.options import EstimateOptions
from tumblescan.bearings.simulate import SimulationConfig, invalid_variants, simulate
from tumblescan.errors import InputError

LOCAL = simulate(SimulationConfig(scene="paper", seed=1, frames=3)).input
ECEF = simulate(SimulationConfig(scene="leo", seed=1, frames=3, targets=3)).input
CASES = [(f"local-{n}", t, f) for n, t, f in invalid_variants(LOCAL)] + [
    (f"ecef-{n}", t, f) for n, t, f in invalid_variants(ECEF)
]


@pytest.mark.parametrize(("name", "text", "field"), CASES, ids=[c[0] for c in CASES])
def test_invalid_input_is_refused_naming_the_field(name: str, text: str, field: str) -> None:
    with pytest.raises(InputError) as err:
        parse_input(load_json(text))
    assert err.value.code == "invalid_input"
    assert err.value.field == field
    assert str(err.value).startswith(field)


def test_the_rules_cover_the_contracts_list() -> None:
    names = {n for n, _, _ in invalid_variants(LOCAL)}
    for rule in (
        "schema",
        "frame",
        "units_angle",
        "three_stations",
        "duplicate_station",
        "coincident_stations",
        "missing_position",
        "missing_geodetic",
        "lat_range",
        "lon_range",
        "sigma_missing",
        "sigma_zero",
        "sigma_tiny",
        "position_sigma_huge",
        "sigma_large",
        "el_above_90",
        "az_nan",
        "el_inf",
        "az_text",
        "duplicate_detection",
        "unknown_station",
        "t_not_increasing",
        "t_too_close",
        "t_far_from_epoch",
        "duplicate_index",
    ):
        assert rule in names


def test_valid_documents_parse() -> None:
    assert len(parse_input(LOCAL).frames) == 3
    inp = parse_input(ECEF)
    assert inp.frame == "ecef" and inp.stations[0].geodetic is not None


def test_an_azimuth_in_0_360_and_missing_or_empty_station_lists_are_fine() -> None:
    doc = copy.deepcopy(LOCAL)
    det = doc["frames"][0]["detections"]["S1"][0]
    det["az_deg"] = det["az_deg"] % 360.0 + 360.0
    doc["frames"][1]["detections"].pop("S2")
    doc["frames"][2]["detections"]["S1"] = []
    result = estimate(parse_input(doc))
    assert result["frames"][1]["targets"] == [] and result["frames"][2]["targets"] == []
    reference = estimate(parse_input(LOCAL))
    np.testing.assert_allclose(
        result["frames"][0]["targets"][0]["position_m"], reference["frames"][0]["targets"][0]["position_m"], atol=1e-6
    )


def test_too_many_detections_is_too_large() -> None:
    with pytest.raises(TooLargeError) as err:
        parse_input(LOCAL, Limits(max_detections_per_station_frame=2))
    assert err.value.code == "too_large"
    with pytest.raises(TooLargeError):
        parse_input(LOCAL, Limits(max_detections_total=12))


JUNK: list[Any] = [None, True, "x", -1, 0, 1e308, -1e308, 1e-300, [], {}, [1, 2], {"a": 1}, 95.0, -400.0, 12345678]


def _paths(node: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    out = [prefix]
    if isinstance(node, dict):
        for k, v in node.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node[:2]):
            out += _paths(v, (*prefix, i))
    return out


@pytest.mark.filterwarnings("error::RuntimeWarning")  # an overflow means a number got past the door unchecked
@pytest.mark.parametrize("doc", [LOCAL, ECEF], ids=["local", "ecef"])
def test_mutated_documents_either_run_or_are_refused_never_crash(doc: dict[str, Any]) -> None:
    rng = np.random.default_rng(0)
    small = copy.deepcopy(doc)
    small["frames"] = small["frames"][:2]
    paths = _paths(small)[1:]
    for _ in range(250):
        d = copy.deepcopy(small)
        path = paths[int(rng.integers(len(paths)))]
        node = d
        for key in path[:-1]:
            node = node[key]
        if rng.uniform() < 0.15 and isinstance(node, dict):
            node.pop(path[-1])
        else:
            node[path[-1]] = JUNK[int(rng.integers(len(JUNK)))]
        try:
            inp = parse_input(load_json(json.dumps(d)))
        except InputError as exc:
            assert exc.code in ("invalid_input", "too_large") and exc.field
            continue
        for method in ("ml", "paper"):
            result = estimate(inp, EstimateOptions(method=method))
            json.dumps(result, allow_nan=False)


@pytest.mark.parametrize(
    ("where", "field"),
    [
        (lambda d: d, "comment"),
        (lambda d: d["stations"][0], "stations[0].sigma_az"),
        (lambda d: d["frames"][1], "frames[1].time"),
        (lambda d: d["frames"][0]["detections"]["S1"][0], "frames[0].detections.S1[0].sigma_az"),
    ],
)
def test_a_field_the_format_does_not_have_is_refused_by_name(where: Any, field: str) -> None:
    # A misspelt per-detection "sigma_az" was ignored and the station's sigma used instead.
    doc = copy.deepcopy(LOCAL)
    where(doc)[field.rsplit(".", 1)[-1]] = 0.5
    with pytest.raises(InputError) as err:
        parse_input(doc)
    assert err.value.code == "invalid_input" and err.value.field == field and "is not a field" in str(err.value)


def test_ecef_geodetic_refuses_unknown_fields_too() -> None:
    doc = copy.deepcopy(ECEF)
    doc["stations"][1]["geodetic"]["alt_m"] = 10.0
    with pytest.raises(InputError) as err:
        parse_input(doc)
    assert err.value.field == "stations[1].geodetic.alt_m"
