"""The dense refinement's Levenberg-Marquardt step (linescan.dense.damping)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from tumblescan.linescan.dense.damping import LM_FIRST_TIGHT, LM_START, LM_TRIES, damped_step


def _quadratic(H: np.ndarray, x_min: np.ndarray) -> Callable[[np.ndarray], float]:
    def cost(x: np.ndarray) -> float:
        d = x - x_min
        return float(d @ H @ d)

    return cost


def test_undamped_step_reaches_a_quadratic_minimum() -> None:
    H = np.array([[4.0, 1.0], [1.0, 3.0]])
    x_min = np.array([0.3, -0.7])
    cost = _quadratic(H, x_min)
    x0 = np.zeros(2)
    g = -H @ (x0 - x_min)
    taken = damped_step(H, g, LM_START, cost(x0), lambda y: (cost(x0 + y), x0 + y))
    assert taken is not None
    lam, x = taken
    np.testing.assert_allclose(x, x_min, atol=1e-12)
    assert lam == LM_START


def test_overshooting_step_is_shortened_before_damping() -> None:
    # The model's step ends at (1, 1); the true cost has four times its curvature, about (0.3, 0.3).
    H = np.eye(2)
    x_min = np.array([1.0, 1.0])
    true_cost = _quadratic(4 * H, 0.3 * x_min)
    x0 = np.zeros(2)
    seen: list[float] = []

    def trial(y: np.ndarray) -> tuple[float, np.ndarray]:
        seen.append(float(np.linalg.norm(y)))
        return true_cost(x0 + y), x0 + y

    taken = damped_step(H, x_min, LM_START, true_cost(x0), trial)
    assert taken is not None
    lam, x = taken
    # The full step raises the cost (0.72 -> 3.92), half of it lowers it (0.32).
    np.testing.assert_allclose(seen, [np.sqrt(2), np.sqrt(2) / 2])
    np.testing.assert_allclose(x, [0.5, 0.5])
    assert lam == LM_START


def test_damping_tightens_then_gives_up_on_a_rising_cost() -> None:
    H = np.eye(2)
    g = np.array([1.0, 0.0])
    lams: list[float] = []

    def trial(y: np.ndarray) -> tuple[float, None]:
        lams.append(float(np.linalg.norm(y)))
        return 1.0 + float(np.linalg.norm(y)), None  # every step raises the cost

    assert damped_step(H, g, LM_START, 1.0, trial) is None
    # Four shortened undamped steps, then damped steps that shrink as the damping tightens.
    np.testing.assert_allclose(lams[:4], [1.0, 0.5, 0.25, 0.125])
    np.testing.assert_allclose(lams[4], 1.0 / (1.0 + LM_FIRST_TIGHT))
    assert len(lams) == 4 + LM_TRIES - 1 and np.all(np.diff(lams[4:]) < 0)
