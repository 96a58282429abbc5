"""Finding members: lines grown from strips, side by side or one at a time."""

from __future__ import annotations

import numpy as np
import pytest

from tumblescan.linescan.dense import members as members_module
from tumblescan.linescan.dense.members import _members, fit_line, fit_lines


def _strips(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[set[int]]]:
    """Strips of three wires (centres 20 cm apart along each, a few mm off it, seen in 5 frames),
    two of them crossing, and 30 strips scattered at random; the wires' strip indices."""
    rng = np.random.default_rng(seed)
    wires = [
        (np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0])),
        (np.array([0.0, 0.0, 0.0]), np.array([0.0, 0.6, 0.8])),
        (np.array([0.0, 3.0, 1.0]), np.array([0.6, 0.0, -0.8])),
    ]
    centre: list[np.ndarray] = []
    direction: list[np.ndarray] = []
    frame: list[int] = []
    truth: list[set[int]] = []
    for c, d in wires:
        s = np.arange(-2.0, 2.0, 0.2)
        start = len(centre)
        for f, t in enumerate(s):
            centre.append(c + t * d + rng.normal(0, 0.004, 3))
            tilt = d + rng.normal(0, 0.03, 3)
            direction.append(tilt / np.linalg.norm(tilt))
            frame.append(f % 5)
        truth.append(set(range(start, len(centre))))
    for _ in range(30):
        centre.append(rng.uniform(-3, 3, 3) + np.array([0.0, 6.0, 0.0]))
        d = rng.normal(size=3)
        direction.append(d / np.linalg.norm(d))
        frame.append(int(rng.integers(5)))
    weight = rng.uniform(5, 20, len(centre))
    return np.array(centre), np.array(direction), weight, np.array(frame), truth


@pytest.mark.parametrize("per_pass", [None, 1, 7])
def test_members_are_the_wires_however_many_lines_grow_at_once(
    monkeypatch: pytest.MonkeyPatch, per_pass: int | None
) -> None:
    centre, direction, weight, frame, truth = _strips(3)
    if per_pass is not None:
        monkeypatch.setattr(members_module, "MAX_SUPPORT_ENTRIES", per_pass * len(centre))
    found = _members(centre, direction, weight, frame, surfel_m=0.1, across_m=0.05)
    assert len(found) == 3
    # Every wire is one member; where two cross, the strip at the crossing goes to one of them.
    for member in found:
        best = max(truth, key=lambda t: len(t & set(member.tolist())))
        assert len(best ^ set(member.tolist())) <= 1


def test_lines_fitted_side_by_side_are_each_line_fitted_alone() -> None:
    rng = np.random.default_rng(1)
    y = rng.normal(size=(50, 3)) * np.array([2.0, 0.1, 0.05]) + np.array([1.0, -2.0, 3.0])
    w = rng.uniform(0, 1, (4, 50)) * (rng.uniform(size=(4, 50)) > 0.3)
    c, d = fit_lines(y, w)
    for k in range(4):
        on = w[k] > 0
        c_k, d_k = fit_line(y[on], w[k][on])
        np.testing.assert_allclose(c[k], c_k, atol=1e-12)
        np.testing.assert_allclose(d[k], d_k, atol=1e-10)
