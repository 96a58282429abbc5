"""Numbers with their sigma, as a person reads them: to the decimal of the sigma's second
significant digit (0.0213 -> 3 decimals, 2.05 -> 1, 120 -> 0). Finer digits are noise; coarser
ones hide what the sigma says."""

from __future__ import annotations

import math


def sigma_decimals(sigma: float | None, *, default: int = 3, most: int = 6) -> int:
    """Decimals that show ``sigma`` to two significant digits, 0 to ``most``; ``default`` when
    there is no positive finite sigma."""
    if sigma is None or not math.isfinite(sigma) or sigma <= 0:
        return default
    return min(most, max(0, 1 - math.floor(math.log10(sigma))))


def with_sigma(value: float, sigma: float | None, unit: str, *, default: int = 3) -> str:
    """``value ± sigma unit``, both to the sigma's second significant digit; ``value unit`` at
    ``default`` decimals without a sigma."""
    d = sigma_decimals(sigma, default=default)
    if sigma is None or not math.isfinite(sigma):
        return f"{value:.{d}f} {unit}"
    return f"{value:.{d}f} ± {sigma:.{d}f} {unit}"
