"""Which start the frames estimator keeps: another start is tried when a motion fits poorly or
fails the two-frame-count check, never because a frame had nothing to match."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from tumblescan.linescan.dense import estimate as est
from tumblescan.linescan.validation import Similarity


@dataclass
class FakeFit:
    scale: float
    frame_rms_m: np.ndarray


def script(monkeypatch: pytest.MonkeyPatch, outcomes: list[tuple[float, bool, int]]) -> list[str]:
    """Each start in turn fits with (residual scale, check passed, frames without a match)."""
    made: list[str] = []
    monkeypatch.setattr(est, "vote", lambda *a: "vote")
    monkeypatch.setattr(est, "consensus_start", lambda *a: "consensus")
    monkeypatch.setattr(est, "_swarm", lambda *a: "swarm")

    def solve(setup: Any, pairs: Any, start: str, warnings: list[str], *, path: str) -> Any:
        made.append(start)
        scale, _, unmatched = outcomes[len(made) - 1]
        rms = np.r_[np.full(unmatched, np.nan), np.full(10 - unmatched, 0.02)]
        return est._Solve(FakeFit(scale, rms), None, 10, path)  # type: ignore[arg-type]

    def judged(setup: Any, solve: Any, n2: int, warnings: list[str]) -> Any:
        passed = outcomes[len(made) - 1][1]
        check = Similarity(passed, 1.0 if passed else 9.0, 3.0, "covariance")
        return est._Attempt(solve, solve.fit, check, warnings)

    monkeypatch.setattr(est, "_solve", solve)
    monkeypatch.setattr(est, "_judged", judged)
    return made


class Setup:
    mid = np.arange(10.0)
    opts = type("O", (), {"seed": 0})()

    def progress(self, stage: str, fraction: float) -> None:
        pass


def test_a_failed_check_leads_to_the_next_start(monkeypatch: pytest.MonkeyPatch) -> None:
    made = script(monkeypatch, [(1.0, False, 0), (1.0, True, 0), (1.0, True, 0)])
    best, warnings, attempts = est._best_attempt(Setup(), None, 7)  # type: ignore[arg-type]
    assert made == ["vote", "consensus"] and attempts == 2
    assert best.solve.path == "registration+consensus+dense"
    assert "two-frame-count check failed" in warnings[-1] and "the motion comes from" in warnings[-1]


def test_a_frame_without_a_match_is_not_a_reason_for_another_start(monkeypatch: pytest.MonkeyPatch) -> None:
    made = script(monkeypatch, [(1.0, True, 1), (1.0, True, 0), (1.0, True, 0)])
    _, warnings, attempts = est._best_attempt(Setup(), None, 7)  # type: ignore[arg-type]
    assert made == ["vote"] and attempts == 1 and warnings == []


def test_when_no_start_is_sound_the_least_flawed_is_kept_and_said(monkeypatch: pytest.MonkeyPatch) -> None:
    made = script(monkeypatch, [(8.0, True, 0), (1.1, False, 0), (20.0, False, 0)])
    best, warnings, attempts = est._best_attempt(Setup(), None, 7)  # type: ignore[arg-type]
    assert made == ["vote", "consensus", "swarm"] and attempts == 3
    assert best.solve.path == "registration+consensus+dense"  # not poor beats a passed check on a poor fit
    assert "no start was sound" in warnings[-1]


def test_a_start_where_the_last_fit_ended_is_not_refined_again(monkeypatch: pytest.MonkeyPatch) -> None:
    # The first motion fails the check; the consensus starts 0.6 deg from where it ended and
    # would end there again, so only the swarm's start (29 deg off) is refined.
    x = np.array([0.3, 1.0, 0.5, 1.2, 0.8, 0.1, 0.0, 0.0, 50.0])
    begins = {"vote": x, "consensus": x + [0.01, 0, 0, 0, 0.01, 0, 0, 0, 0], "swarm": x + [0.5, 0, 0, 0, 0, 0, 0, 0, 0]}

    def start_of(name: str) -> Any:
        guess = est.InitialGuess(x=begins[name], x_spin_only=begins[name], cone_collapsed=False, passes=1)
        return lambda *a: est.Start(guess=guess, inliers=np.ones(3, bool))

    for name, attr in (("vote", "vote"), ("consensus", "consensus_start"), ("swarm", "_swarm")):
        monkeypatch.setattr(est, attr, start_of(name))
    refined: list[np.ndarray] = []

    def solve(setup: Any, pairs: Any, start: Any, warnings: list[str], *, path: str) -> Any:
        refined.append(start.guess.x)
        fit = type("Fit", (FakeFit,), {"x": start.guess.x})(1.0, np.full(10, 0.02))
        return est._Solve(fit, start.guess, 10, path)

    def judged(setup: Any, solve: Any, n2: int, warnings: list[str]) -> Any:
        passed = len(refined) == 2
        return est._Attempt(solve, solve.fit, Similarity(passed, 1.0, 3.0, "covariance"), warnings)

    monkeypatch.setattr(est, "_solve", solve)
    monkeypatch.setattr(est, "_judged", judged)
    best, warnings, attempts = est._best_attempt(Setup(), None, 7)  # type: ignore[arg-type]
    assert len(refined) == 2 and np.array_equal(refined[1], begins["swarm"]) and attempts == 3
    assert best.solve.path == "registration+swarm+dense"
    assert "not refined again" in warnings[-1]
