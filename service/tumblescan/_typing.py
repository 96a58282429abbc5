"""Type aliases shared by every package (arrays carry their unit in the variable's name)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

# A progress reporter: (stage name, fraction done in [0, 1]). In a job it is also the
# cancellation point, so long loops should call it between steps.
Progress = Callable[[str, float], None]


def no_progress(stage: str, fraction: float) -> None:
    """The reporter used when nobody listens."""
