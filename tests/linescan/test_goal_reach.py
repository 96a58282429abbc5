"""The bench's odds that an efficient estimator meets issue 20's goal: the count's distribution and
the resampled benches, against cases worked by hand."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from bench.linescan.goal_reach import (
    INFLATIONS,
    Reach,
    count_distribution,
    goal_met_exactly,
    goal_met_resampled,
    inflation_rows,
    summary,
)


def test_count_distribution_is_the_binomial_when_every_case_is_alike() -> None:
    from scipy.stats import binom

    assert np.allclose(count_distribution(np.full(20, 0.9)), binom.pmf(np.arange(21), 20, 0.9))


def test_count_distribution_of_unequal_cases_by_hand() -> None:
    # Two cases, 0.5 and 0.9: none 0.05, one 0.5, both 0.45.
    assert np.allclose(count_distribution(np.array([0.5, 0.9])), [0.05, 0.5, 0.45])


def test_goal_needs_19_of_20() -> None:
    p = np.full(20, 0.95)
    # P(at least 19 of 20) = 0.95^20 + 20 * 0.05 * 0.95^19.
    assert goal_met_exactly(p) == pytest.approx(0.95**20 + 20 * 0.05 * 0.95**19)
    # One sure miss leaves no room for another.
    assert goal_met_exactly(np.r_[np.ones(19), 0.0]) == pytest.approx(1.0)
    assert goal_met_exactly(np.r_[np.ones(18), 0.0, 0.0]) == pytest.approx(0.0)


def test_resampled_benches_agree_with_the_exact_odds_when_every_motion_is_alike() -> None:
    rng = np.random.default_rng(1)
    resampled = goal_met_resampled([np.full(50, 0.97), np.full(50, 0.97)], 10, rng)
    assert resampled == pytest.approx(goal_met_exactly(np.full(20, 0.97)), abs=0.01)


def test_summary_multiplies_the_shapes_odds() -> None:
    reaches = [
        Reach(shape, distance, seed, planes=p, known_shape=1.0)
        for shape, p in (("a", 1.0), ("b", 0.95))
        for distance in (50.0, 100.0)
        for seed in range(10)
    ]
    rows, everything = summary(reaches, {"a": 1.0, "b": 0.8})
    assert [r[0] for r in rows] == ["a", "b"]
    assert rows[1][-1] == "80 %"
    assert everything["planes"]["bench seeds"] == pytest.approx(goal_met_exactly(np.full(20, 0.95)))
    assert everything["known_shape"]["bench seeds"] == pytest.approx(1.0)


def test_inflation_rows_give_each_factors_share_and_odds_on_the_swept_motions() -> None:
    shares = dict(zip(map(str, INFLATIONS), (0.98, 0.96, 0.9, 0.8), strict=True))
    reaches = [
        Reach("a", distance, seed, planes=0.99, known_shape=1.0, inflated=shares)
        for distance in (50.0, 100.0)
        for seed in range(10)
    ]
    # A sweep saved before the inflated shares were measured has no row.
    reaches += [Reach("old", 50.0, seed, planes=0.99, known_shape=1.0) for seed in range(10)]
    rows, at_once = inflation_rows(reaches + [replace(r, shape="b") for r in reaches[:20]], {"a": 0.9})
    assert len(rows) == 2
    name, cases, *columns, ours = rows[0]
    assert (name, cases, ours) == ("a", 20, "90.0 %")
    expected = [0.99, 0.98, 0.96, 0.9, 0.8]
    assert columns == [f"{100 * p:.1f} % ({goal_met_exactly(np.full(20, p)):.2f})" for p in expected]
    # Two alike shapes: every shape at once is the square of one's odds.
    assert at_once == pytest.approx([goal_met_exactly(np.full(20, p)) ** 2 for p in expected])
