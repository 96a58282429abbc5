"""Levenberg-Marquardt damping for the dense refinement (:mod:`.refine`).

One step solves

    (H + lam diag H) y = g

for the smallest damping ``lam`` (from the last step's) whose step ``y`` does not raise the
cost. The damping starts at zero, tightens on a rise of the cost, relaxes on success, and goes
back to zero once relaxed below its first tightening: a damping that lingers at 1e-6 of the
diagonal still crawls along a nearly degenerate direction. An undamped step that raises the
cost is shortened before it is damped: damping turns it towards the gradient, off the floor of
a valley that a shorter step stays on.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

import numpy as np

from ..._typing import FloatArray

LM_START = 0.0
LM_FIRST_TIGHT = 1e-4
LM_TIGHTEN = 10.0
LM_RELAX = 3.0
LM_TRIES = 10
# The undamped step, then these shares of it, before any damping.
GN_FRACTIONS = (1.0, 0.5, 0.25, 0.125)

Trial = TypeVar("Trial")


def damped_step(
    H: FloatArray, g: FloatArray, lam: float, before: float, trial: Callable[[FloatArray], tuple[float, Trial]]
) -> tuple[float, Trial] | None:
    """The first step that does not raise the cost, in the order above.

    H: (n, n) Gauss-Newton matrix and g: (n,) minus the gradient, in the step's coordinates.
    lam: the damping to start from (relative to ``diag H``). before: the cost at the current
    parameters. trial(y): the cost after step ``y`` (n,) and what the caller keeps of that trial
    (the moved parameters, say). Returns the damping for the next step and the accepted trial's
    keep, or None when no damping up to ``LM_TRIES`` tightenings lowers the cost.
    """
    D = np.diag(np.diag(H))
    for _ in range(LM_TRIES):
        step = np.linalg.lstsq(H + lam * D, g, rcond=None)[0]
        for fraction in GN_FRACTIONS if lam == 0 else (1.0,):
            cost, kept = trial(np.asarray(fraction * step, dtype=float))
            if cost <= before:
                relaxed = lam / LM_RELAX
                return (relaxed if relaxed >= LM_FIRST_TIGHT else LM_START), kept
        lam = max(lam * LM_TIGHTEN, LM_FIRST_TIGHT)
    return None
