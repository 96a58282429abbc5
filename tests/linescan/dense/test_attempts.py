"""Which start the frames estimator keeps: another start is tried when a motion fits poorly or
fails the two-frame-count check, never because a frame had nothing to match."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

from tumblescan.linescan.dense import attempts as est
from tumblescan.linescan.validation import Similarity


@dataclass
class FakeFit:
    scale: float
    frame_rms_m: np.ndarray
    x: np.ndarray = field(default_factory=lambda: np.array([0.3, 1.0, 0.5, 1.2, 0.8, 0.1, 0.0, 0.0, 50.0]))
    residuals: int = 1000
    cov: np.ndarray = field(default_factory=lambda: np.eye(9))
    given_up: int = 0
    given_up_scale: float = float("nan")


def script(monkeypatch: pytest.MonkeyPatch, outcomes: list[tuple[float, bool, int]]) -> list[str]:
    """Each start in turn fits with (residual scale, check passed, frames without a match)."""
    made: list[str] = []
    monkeypatch.setattr(est, "vote", lambda *a: "vote")
    monkeypatch.setattr(est, "consensus_start", lambda *a: "consensus")
    monkeypatch.setattr(est, "_swarm", lambda *a: "swarm")

    def solve(setup: Any, pairs: Any, start: str, *, path: str, give_up: bool = True) -> Any:
        made.append(start)
        scale, _, unmatched = outcomes[len(made) - 1]
        rms = np.r_[np.full(unmatched, np.nan), np.full(10 - unmatched, 0.02)]
        # Each start ends at its own motion, tens of degrees from the others'.
        x = np.array([0.3 + 0.5 * len(made), 1.0, 0.5, 1.2, 0.8, 0.1, 0.0, 0.0, 50.0])
        return est.Solve(FakeFit(scale, rms, x), None, 10, 10, path)  # type: ignore[arg-type]

    def judged(setup: Any, solve: Any, n2: int) -> Any:
        passed = outcomes[len(made) - 1][1]
        check = Similarity(passed, 1.0 if passed else 9.0, 3.0, "covariance")
        return est.Attempt(solve, solve.fit, check, [])

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
    best, warnings, attempts = est.best_attempt(Setup(), None, 7)  # type: ignore[arg-type]
    assert made == ["vote", "consensus"] and attempts == 2
    assert best.solve.path == "registration+consensus+dense"
    assert "two-frame-count check failed" in warnings[-1] and "the motion comes from" in warnings[-1]


def test_a_frame_without_a_match_is_not_a_reason_for_another_start(monkeypatch: pytest.MonkeyPatch) -> None:
    made = script(monkeypatch, [(1.0, True, 1), (1.0, True, 0), (1.0, True, 0)])
    _, warnings, attempts = est.best_attempt(Setup(), None, 7)  # type: ignore[arg-type]
    assert made == ["vote"] and attempts == 1 and warnings == []


def test_most_frames_without_a_match_lead_to_the_next_start(monkeypatch: pytest.MonkeyPatch) -> None:
    # 6 of 10 frames unmatched: the motion, not the views, is at fault; 5 of 10 is still the views.
    made = script(monkeypatch, [(1.0, True, 6), (1.0, True, 0), (1.0, True, 0)])
    best, warnings, attempts = est.best_attempt(Setup(), None, 7)  # type: ignore[arg-type]
    assert made == ["vote", "consensus"] and attempts == 2
    assert "6 of 10 frames matched no surface in another" in warnings[-1]
    assert best.solve.path == "registration+consensus+dense"
    made = script(monkeypatch, [(1.0, True, 5), (1.0, True, 0), (1.0, True, 0)])
    assert est.best_attempt(Setup(), None, 7)[2] == 1  # type: ignore[arg-type]


def test_when_no_start_is_sound_the_least_flawed_is_kept_and_said(monkeypatch: pytest.MonkeyPatch) -> None:
    made = script(monkeypatch, [(8.0, True, 0), (1.1, False, 0), (20.0, False, 0)])
    best, warnings, attempts = est.best_attempt(Setup(), None, 7)  # type: ignore[arg-type]
    assert made == ["vote", "consensus", "swarm"] and attempts == 3
    assert best.solve.path == "registration+consensus+dense"  # not poor beats a passed check on a poor fit
    assert "no start was sound" in warnings[-1]


def scripted_starts(
    monkeypatch: pytest.MonkeyPatch, begins: dict[str, np.ndarray], ends: dict[str, np.ndarray], scales: list[float]
) -> list[np.ndarray]:
    """Starts at ``begins``; the n-th refined start ends at ``ends`` of its name with residual
    scale ``scales[n]``, and only the second one refined passes the check."""
    for name, attr in (("vote", "vote"), ("consensus", "consensus_start"), ("swarm", "_swarm")):
        guess = est.InitialGuess(x=begins[name], x_spin_only=begins[name], cone_collapsed=False, passes=1)
        monkeypatch.setattr(est, attr, lambda *a, g=guess: est.Start(guess=g, inliers=np.ones(3, bool)))
    refined: list[np.ndarray] = []

    def solve(setup: Any, pairs: Any, start: Any, *, path: str, give_up: bool = True) -> Any:
        name = next(k for k, v in begins.items() if v is start.guess.x)
        fit = FakeFit(scales[len(refined)], np.full(10, 0.02), ends[name])
        refined.append(start.guess.x)
        return est.Solve(fit, start.guess, 10, 10, path)  # type: ignore[arg-type]

    def judged(setup: Any, solve: Any, n2: int) -> Any:
        passed = len(refined) == 2
        return est.Attempt(solve, solve.fit, Similarity(passed, 1.0, 3.0, "covariance"), [])

    monkeypatch.setattr(est, "_solve", solve)
    monkeypatch.setattr(est, "_judged", judged)
    return refined


X = np.array([0.3, 1.0, 0.5, 1.2, 0.8, 0.1, 0.0, 0.0, 50.0])
NEAR = X + [0.01, 0, 0, 0, 0.01, 0, 0, 0, 0]  # 0.6 deg away: the same basin
FAR = X + [0.5, 0, 0, 0, 0, 0, 0, 0, 0]  # 29 deg away


def test_a_start_where_a_poor_fit_ended_is_not_refined_again(monkeypatch: pytest.MonkeyPatch) -> None:
    # The first motion fits poorly; the consensus starts 0.6 deg from where it ended and would
    # end there again, so only the swarm's start (29 deg off) is refined.
    begins = {"vote": X, "consensus": NEAR, "swarm": FAR}
    refined = scripted_starts(monkeypatch, begins, begins, [8.0, 1.0])
    best, warnings, attempts = est.best_attempt(Setup(), None, 7)  # type: ignore[arg-type]
    assert len(refined) == 2 and np.array_equal(refined[1], FAR) and attempts == 3
    assert best.solve.path == "registration+swarm+dense"
    assert "not refined again" in warnings[-1]


def test_a_check_failure_two_starts_agree_on_ends_the_search(monkeypatch: pytest.MonkeyPatch) -> None:
    # The first motion fits the points but fails the check; the consensus starts where it ended:
    # the swarm is not tried, and the failure is reported.
    begins = {"vote": X, "consensus": NEAR, "swarm": FAR}
    refined = scripted_starts(monkeypatch, begins, begins, [1.0, 1.0])
    best, warnings, attempts = est.best_attempt(Setup(), None, 7)  # type: ignore[arg-type]
    assert len(refined) == 1 and attempts == 2 and best.solve.path == "registration+cone+dense"
    assert "no start was sound" in warnings[-1] and best.problem() == "the two-frame-count check failed"


def test_a_second_start_that_ends_where_the_first_failed_ends_the_search(monkeypatch: pytest.MonkeyPatch) -> None:
    # The consensus starts far away yet ends where the vote's motion did, which failed the check.
    refined = scripted_starts(
        monkeypatch, {"vote": X, "consensus": FAR, "swarm": FAR + 0.3}, {"vote": X, "consensus": NEAR}, [1.0, 1.0]
    )
    monkeypatch.setattr(
        est,
        "_judged",
        lambda s, solve, n2: est.Attempt(solve, solve.fit, Similarity(False, 9.0, 3.0, "covariance"), []),
    )
    _, warnings, attempts = est.best_attempt(Setup(), None, 7)  # type: ignore[arg-type]
    assert len(refined) == 2 and attempts == 2
    assert "ended where the motion above did" in warnings[-1]


def _unmatched_first(monkeypatch: pytest.MonkeyPatch, starts_unmatched: int) -> list[str]:
    """The first ``starts_unmatched`` starts match no patch of another frame; the rest fit."""
    made = script(monkeypatch, [(1.0, True, 0)] * 3)
    solve: Any = est._solve  # the scripted one

    def unmatched(setup: Any, pairs: Any, start: str, *, path: str, give_up: bool = True) -> Any:
        if len(made) < starts_unmatched:
            made.append(start)
            raise est.NoSurfacesError("no planar patch of one frame could be matched in another", field="file")
        return solve(setup, pairs, start, path=path, give_up=give_up)

    monkeypatch.setattr(est, "_solve", unmatched)
    return made


def test_a_start_from_which_no_patch_matched_leads_to_the_next(monkeypatch: pytest.MonkeyPatch) -> None:
    # A fast tumbler's wrong start can map every patch away from the others; that says nothing of
    # the frames while another start remains.
    made = _unmatched_first(monkeypatch, 1)
    best, warnings, attempts = est.best_attempt(Setup(), None, 7)  # type: ignore[arg-type]
    assert made == ["vote", "consensus"] and attempts == 2
    assert best.solve.path == "registration+consensus+dense"
    assert any("registration+cone+dense: no planar patch" in w for w in warnings)


def test_no_patch_matched_from_any_start_is_the_frames_fault(monkeypatch: pytest.MonkeyPatch) -> None:
    made = _unmatched_first(monkeypatch, 3)
    with pytest.raises(est.NoSurfacesError, match="no planar patch"):
        est.best_attempt(Setup(), None, 7)  # type: ignore[arg-type]
    assert made == ["vote", "consensus", "swarm"]


def test_a_spin_only_refit_that_matches_nothing_leaves_the_fit_that_does(monkeypatch: pytest.MonkeyPatch) -> None:
    # Seen on the long array at 50 m (seed 8): the Wald test found no precession, the spin-only
    # refit matched no surface across frames, and the result read 30.86 +- 0 deg/s with a
    # passed check.
    full = FakeFit(1.05, np.full(10, 0.02))
    lost = FakeFit(0.0, np.full(10, np.nan), residuals=0)
    monkeypatch.setattr(est, "precession_p_value", lambda x, cov: 0.99)
    monkeypatch.setattr(est, "refine_dense", lambda *a, **k: lost)
    setup = type("S", (Setup,), {"data": type("D", (), {"n_frames": 10})(), "noise": None})()
    setup.opts = type("O", (), {"seed": 0, "model": "auto", "significance": 0.05, "dense": None})()
    solve = est.Solve(full, type("G", (), {"x_spin_only": full.x})(), 10, 10, "registration+cone+dense")  # type: ignore[arg-type]
    attempt = est._judged(setup, solve, 10)
    assert attempt.fit is full
    assert "spin-only refit does not fit the frames (no surface of one frame matched in another)" in attempt.warnings[0]
    # Another start should try to pin the precession down; this one ranks after a sound one.
    doubted = attempt
    assert doubted.problem() is not None and "spin-only refit does not fit" in doubted.problem()  # type: ignore[operator]
    # And such a fit is never taken as sound.
    assert est.poor_fit(lost) is not None  # type: ignore[arg-type]
    # A spin-only refit that fits is reported as before.
    fits = FakeFit(1.0, np.full(10, 0.02))
    monkeypatch.setattr(est, "refine_dense", lambda *a, **k: fits)
    attempt = est._judged(setup, solve, 10)
    assert attempt.fit is fits and "reporting the spin-only model" in attempt.warnings[0]
    assert attempt.problem() is None and attempt.flaws() < doubted.flaws()


JUDGED = est._judged


def _judging_setup(monkeypatch: pytest.MonkeyPatch, scales: list[float]) -> tuple[Any, list[float]]:
    """The real judgement (significant precession, so no spin-only refit) of starts whose fits have
    residual ``scales`` in turn; every check passes, and the scale of each fit checked is recorded."""
    checked: list[float] = []
    monkeypatch.setattr(est, "precession_p_value", lambda x, cov: 0.0)

    def validate(setup: Any, n2: int, fit: Any) -> Similarity:
        checked.append(fit.scale)
        return Similarity(True, 1.0, 3.0, "covariance")

    monkeypatch.setattr(est, "_validate", validate)
    script(monkeypatch, [(s, True, 0) for s in scales])
    monkeypatch.setattr(est, "_judged", JUDGED)
    setup = type("S", (Setup,), {"data": type("D", (), {"n_frames": 10})(), "noise": None})()
    setup.opts = type("O", (), {"seed": 0, "model": "auto", "significance": 0.05, "dense": None})()
    return setup, checked


def test_a_poor_fit_is_not_checked_while_another_start_may_be_sound(monkeypatch: pytest.MonkeyPatch) -> None:
    # Seen on the long array at 100 m (seed 1): the vote's motion left residuals 22.8 times their
    # size and its check cost 2.8 s of the job's 19 s before the consensus's sound motion.
    setup, checked = _judging_setup(monkeypatch, [22.8, 1.0, 1.0])
    best, warnings, attempts = est.best_attempt(setup, None, 7)  # type: ignore[arg-type]
    assert attempts == 2 and checked == [1.0]
    assert best.solve.path == "registration+consensus+dense" and best.check is not None and best.check.passed
    assert "residuals 22.8 times their expected size" in warnings[-1]


def test_when_every_fit_is_poor_each_is_checked_and_the_least_flawed_kept(monkeypatch: pytest.MonkeyPatch) -> None:
    setup, checked = _judging_setup(monkeypatch, [8.0, 5.0, 20.0])
    best, warnings, attempts = est.best_attempt(setup, None, 7)  # type: ignore[arg-type]
    assert attempts == 3 and sorted(checked) == [5.0, 8.0, 20.0]
    assert best.fit.scale == 5.0 and best.check is not None and "no start was sound" in warnings[-1]


def test_every_start_but_the_last_may_be_given_up_early(monkeypatch: pytest.MonkeyPatch) -> None:
    # The last start is refined to the end, so that a job where no start is sound reports a whole
    # refinement among its candidates.
    script(monkeypatch, [(20.0, True, 0)] * 3)
    scripted: Any = est._solve
    flags: list[bool] = []

    def solve(setup: Any, pairs: Any, start: str, *, path: str, give_up: bool) -> Any:
        flags.append(give_up)
        return scripted(setup, pairs, start, path=path, give_up=give_up)

    monkeypatch.setattr(est, "_solve", solve)
    est.best_attempt(Setup(), None, 7)  # type: ignore[arg-type]
    assert flags == [True, True, False]


@pytest.mark.parametrize(("give_up", "full_scale"), [(True, 30.0), (False, 30.0), (True, 1.0)])
def test_the_spin_only_refit_of_a_poor_start_may_be_given_up_as_that_start_may(
    monkeypatch: pytest.MonkeyPatch, give_up: bool, full_scale: float
) -> None:
    # Seen on the long array at 100 m seed 1 from another motion's turns: the vote's refinement
    # was given up after its first stage, and the spin-only refit from the same start ran all three
    # at 32-37 times its residuals' size (7 s) before the next start. From a sound fit's start
    # (``full_scale`` 1) the refit runs to the end: without its precession that start may be off.
    full = FakeFit(full_scale, np.full(10, 0.02), given_up=int(full_scale > 9), given_up_scale=full_scale)
    asked: list[object] = []

    def refit(*args: Any, **kwargs: Any) -> FakeFit:
        asked.append(kwargs.get("give_up_scale"))
        stopped = kwargs.get("give_up_scale") is not None
        return FakeFit(31.9 if stopped else 36.8, np.full(10, 0.02), given_up=int(stopped), given_up_scale=31.9)

    monkeypatch.setattr(est, "precession_p_value", lambda x, cov: 0.99)
    monkeypatch.setattr(est, "refine_dense", refit)
    setup = type("S", (Setup,), {"data": type("D", (), {"n_frames": 10})(), "noise": None})()
    setup.opts = type("O", (), {"seed": 0, "model": "auto", "significance": 0.05, "dense": None})()
    monkeypatch.setattr(est, "_validate", lambda *a: Similarity(True, 1.0, 3.0, "covariance"))
    initial = type("G", (), {"x_spin_only": full.x})()
    solve = est.Solve(full, initial, 10, 10, "registration+cone+dense", give_up=give_up)  # type: ignore[arg-type]
    attempt = est._judged(setup, solve, 10)
    stopped = give_up and full_scale > 9
    assert asked == [est.GIVE_UP_SCALE if stopped else None]
    if full_scale > 9:
        # Both poor: the spin-only refit is reported, and why it is poor.
        why = attempt.problem()
        assert why is not None and ("(given up there)" in why) == stopped, why
    else:
        assert attempt.fit is full and "spin-only refit does not fit" in attempt.warnings[0]


def test_a_given_up_fit_is_poor_whatever_its_own_scale() -> None:
    # The scale a fit reports is its surfel pairs' at the motion it stopped at; the stage it was
    # given up after weighed every row (members' too), and stood over the give-up.
    fit = FakeFit(2.1, np.full(10, 0.02), given_up=2, given_up_scale=12.7)
    why = est.poor_fit(fit)  # type: ignore[arg-type]
    assert why == "residuals 12.7 times their expected size in the second stage of refinement (given up there)"
    assert est.poor_fit(FakeFit(2.1, np.full(10, 0.02))) is None  # type: ignore[arg-type]
