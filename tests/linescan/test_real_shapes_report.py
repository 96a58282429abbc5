"""The real-shapes bench's per-shape calibration: RMS of error over sigma and over the bound."""

from __future__ import annotations

import math

import pytest
from bench.linescan.real_shapes import PARAMS, UNITS, Case, rms_ratio


def _case(err_over_sigma: float, err_over_bound: float, *, spin_only: bool = False) -> Case:
    errors: dict[str, float] = {}
    bound: dict[str, float] = {}
    for p in PARAMS:
        nan = spin_only and p == "precession_axis"
        bound[f"{p}_{UNITS[p]}"] = 0.01
        errors[f"{p}_{UNITS[p]}"] = math.nan if nan else 0.01 * err_over_bound
        errors[f"{p}_sigma"] = math.nan if nan else err_over_sigma
    return Case(
        shape="box", distance_m=50.0, seed=0, errors=errors, within_limits=True, flagged=False, flag="", flags=[],
        worst_sigma=err_over_sigma, points_share=0.8, seconds=1.0, warnings=[], bound=bound, below_bound=False,
        within_bound=True, bound_limits={},
    )  # fmt: skip


def test_rms_ratio_pools_cases_and_parameters() -> None:
    cases = [_case(1.0, 2.0), _case(3.0, 4.0)]
    assert rms_ratio(cases, "sigma") == pytest.approx(math.sqrt((1 + 9) / 2))
    assert rms_ratio(cases, "bound") == pytest.approx(math.sqrt((4 + 16) / 2))


def test_rms_ratio_skips_a_spin_only_case_s_missing_precession_axis() -> None:
    assert rms_ratio([_case(2.0, 5.0, spin_only=True)], "sigma") == pytest.approx(2.0)
    assert rms_ratio([_case(2.0, 5.0, spin_only=True)], "bound") == pytest.approx(5.0)
