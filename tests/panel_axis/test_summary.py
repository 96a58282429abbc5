"""The human-readable result: values to the decimal their σ supports, no ``None``."""

from __future__ import annotations

import pytest

from tumblescan.panel_axis.summary import decimals, sigma_text, with_sigma


@pytest.mark.parametrize(
    ("value", "sigma", "text"),
    [
        (87.48123, 0.0151, "87.481 ± 0.015 deg"),
        (45.17406448265553, 1.6629689836557298, "45.2 ± 1.7 deg"),
        (-56.9481, 0.1645404935633765, "-56.95 ± 0.16 deg"),
        (12.3, 12.0, "12 ± 12 deg"),
        (3.0, 0.0, "3.000 ± 0.000 deg"),
        (90.777, None, "90.777 deg (sigma n/a: paper method)"),
    ],
)
def test_a_value_is_rounded_to_its_sigma(value: float, sigma: float | None, text: str) -> None:
    assert with_sigma(value, sigma) == text


def test_sigma_alone_and_the_decimals_bounds() -> None:
    assert sigma_text(1.6629689836557298) == "sigma 1.7 deg"
    assert sigma_text(None) == "sigma n/a (paper method)"
    assert decimals(1e-12) == 6 and decimals(5e4) == 0
