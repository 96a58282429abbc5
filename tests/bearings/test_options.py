"""The options model, the one source of the option rules for the CLI and the API: an option the
run would not read is refused by name, and every number must be finite."""

from __future__ import annotations

import math

import pytest
from pydantic import ValidationError

from tumblescan.bearings.options import LINKING, ML_ONLY, PAPER_ONLY, EstimateOptions

VALUES = {
    "gate_chi2": 9.0,
    "ambiguity_margin_chi2": 2.0,
    "multi_frame": False,
    "max_angular_rate_deg_s": 3.0,
    "paper_gate_sigma": 3.0,
    "paper_radius_deg": 5.0,
    "max_speed_m_s": 500.0,
    "max_gap_frames": 1,
}


def refusal(**options: object) -> dict:
    with pytest.raises(ValidationError) as err:
        EstimateOptions.model_validate(options)
    (e,) = err.value.errors(include_url=False)
    return dict(e)


@pytest.mark.parametrize(
    ("name", "method"), [(n, "paper") for n in ML_ONLY] + [(n, m) for n in PAPER_ONLY for m in ("ml", None)]
)
def test_an_option_of_the_other_method_is_refused_by_name(name: str, method: str | None) -> None:
    given = {"method": method} if method else {}
    e = refusal(**given, **{name: VALUES[name]})
    assert e["loc"] == (name,) and e["type"] == "option_not_applicable"
    assert f"does not apply to method '{method or 'ml'}'" in e["msg"]


def test_each_methods_own_options_are_accepted() -> None:
    ml = {n: VALUES[n] for n in ML_ONLY if n != "max_angular_rate_deg_s"}
    assert EstimateOptions.model_validate({"method": "ml", **ml}).gate_chi2 == 9.0
    assert EstimateOptions(max_angular_rate_deg_s=3.0).max_angular_rate_deg_s == 3.0
    paper = EstimateOptions.model_validate({"method": "paper", **{n: VALUES[n] for n in PAPER_ONLY}})
    assert paper.paper_gate_sigma == 3.0 and paper.paper_radius_deg == 5.0
    # Left at their defaults, the other method's options are no one's concern.
    assert EstimateOptions(method="paper").model_dump(exclude_unset=True) == {"method": "paper"}


@pytest.mark.parametrize("method", ["ml", "paper"])
def test_every_option_sent_at_its_default_is_accepted(method: str) -> None:
    # A client or form that sends every option: a default changes nothing, so nothing is ignored.
    sent = {**EstimateOptions().model_dump(), "method": method, "link_tracks": False, "multi_frame": False}
    sent = {k: v for k, v in sent.items() if not (method == "paper" and k == "multi_frame")}
    assert EstimateOptions.model_validate(sent).method == method


@pytest.mark.parametrize("name", LINKING)
def test_linking_options_need_linking(name: str) -> None:
    e = refusal(link_tracks=False, **{name: VALUES[name]})
    assert e["loc"] == (name,) and "link_tracks is false" in e["msg"]
    # The paper's method links tracks whatever link_tracks says (its correction works on them).
    EstimateOptions.model_validate({"method": "paper", "link_tracks": False, name: VALUES[name]})
    EstimateOptions.model_validate({"link_tracks": True, name: VALUES[name]})


def test_the_station_track_rate_needs_the_multi_frame_step() -> None:
    e = refusal(multi_frame=False, max_angular_rate_deg_s=3.0)
    assert e["loc"] == ("max_angular_rate_deg_s",) and "multi_frame is false" in e["msg"]


FLOATS = [n for n, f in EstimateOptions.model_fields.items() if f.annotation in (float, "float")]


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, "NaN", "Infinity"])
@pytest.mark.parametrize("name", FLOATS)
def test_every_float_option_must_be_finite(name: str, value: object) -> None:
    method = {"method": "paper"} if name in PAPER_ONLY else {}
    e = refusal(**method, **{name: value})
    assert e["loc"] == (name,) and e["msg"] == "Input should be a finite number"


def test_every_float_option_is_checked() -> None:
    assert set(FLOATS) == {
        "gate_chi2",
        "ambiguity_margin_chi2",
        "low_parallax_deg",
        "max_angular_rate_deg_s",
        "max_speed_m_s",
        "paper_gate_sigma",
        "paper_radius_deg",
    }
