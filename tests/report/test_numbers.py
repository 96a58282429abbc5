"""Numbers printed with their sigma, to the sigma's second significant digit."""

from __future__ import annotations

import math

import pytest

from tumblescan.report.numbers import sigma_decimals, with_sigma


@pytest.mark.parametrize(("sigma", "decimals"), [(0.0213, 3), (2.05, 1), (120.0, 0), (0.1, 2), (1e-9, 6)])
def test_decimals_show_two_significant_digits_of_the_sigma(sigma: float, decimals: int) -> None:
    assert sigma_decimals(sigma) == decimals


@pytest.mark.parametrize("sigma", [None, 0.0, -1.0, math.nan, math.inf])
def test_without_a_usable_sigma_the_default_decimals(sigma: float | None) -> None:
    assert sigma_decimals(sigma, default=4) == 4


def test_value_and_sigma_share_their_decimals() -> None:
    assert with_sigma(91.10153, 0.0082, "deg") == "91.1015 ± 0.0082 deg"
    assert with_sigma(13.3, None, "deg/s") == "13.300 deg/s"
