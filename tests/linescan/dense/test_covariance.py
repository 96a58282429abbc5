"""The dense fit's covariance against the spread of estimates it describes (Monte Carlo)."""

from __future__ import annotations

import numpy as np

from tumblescan.linescan.dense import covariance
from tumblescan.linescan.dense.covariance import cauchy_curvature, sandwich
from tumblescan.linescan.dense.refine import CAUCHY_C

N_PARAMS, PATCHES, PER_PATCH, TRIALS = 3, 10, 40, 400


def _cauchy_fit(J: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, float]:
    """Iteratively reweighted least squares for the Cauchy loss, as the dense fit steps."""
    theta = np.linalg.lstsq(J, y, rcond=None)[0]
    for _ in range(50):
        r = y - J @ theta
        scale = 1.4826 * np.median(np.abs(r))
        w = 1.0 / (1.0 + (r / (CAUCHY_C * scale)) ** 2)
        theta = np.linalg.solve(J.T @ (J * w[:, None]), J.T @ (w * y))
    return theta, CAUCHY_C * 1.4826 * float(np.median(np.abs(y - J @ theta)))


def test_cauchy_curvature_is_the_second_derivative_of_the_loss() -> None:
    e, c, h = np.linspace(-8.0, 8.0, 33), 2.0, 1e-4

    def rho(v: np.ndarray) -> np.ndarray:
        return np.asarray(c**2 / 2 * np.log1p((v / c) ** 2))

    numeric = (rho(e + h) - 2 * rho(e) + rho(e - h)) / h**2
    np.testing.assert_allclose(cauchy_curvature(e, c), numeric, atol=1e-5)


def test_sigmas_match_the_spread_with_few_patches_and_heavy_tails() -> None:
    """Ten patches, each with an error shared by its residuals, and Student-t noise: the
    reported variance matches the estimates' spread (the plain clustered sandwich with the
    reweighting matrix reported about half of it)."""
    rng = np.random.default_rng(3)
    cluster = np.repeat(np.arange(PATCHES), PER_PATCH)
    # Each patch constrains the parameters unequally, as faces of a target do.
    J = rng.normal(size=(PATCHES * PER_PATCH, N_PARAMS)) * rng.uniform(0.3, 3.0, (PATCHES, N_PARAMS))[cluster]
    estimates, variances = [], []
    for _ in range(TRIALS):
        y = rng.standard_t(3, len(J)) + 0.4 * rng.normal(size=PATCHES)[cluster]
        theta, c = _cauchy_fit(J, y)
        cov = sandwich(J, y - J @ theta, np.ones(len(J)), c, cluster, None)
        estimates.append(theta)
        variances.append(np.diag(cov))
    ratio = np.mean(variances, axis=0) / np.var(estimates, axis=0)
    assert np.all((ratio > 0.85) & (ratio < 1.6)), ratio


def test_a_parameter_few_patches_carry_keeps_the_pooled_design_effect() -> None:
    """Twenty patches inform two parameters; the third only three of them (a rate on the
    truss). Every patch errs as a whole. The jackknife alone, of two degrees of freedom for the
    third parameter, reports a sigma that its error exceeds three times over in 35 of 400
    trials; with the pooled design floor 6. The well-carried parameters' mean variances grow by
    about a fifth (their jackknives are noisy too) and stay within 1.6 times their spread."""
    rng = np.random.default_rng(11)
    patches, per_patch, trials = 20, 40, 400
    cluster = np.repeat(np.arange(patches), per_patch)
    J = rng.normal(size=(patches * per_patch, N_PARAMS)) * rng.uniform(0.3, 3.0, (patches, N_PARAMS))[cluster]
    J[:, 2] *= np.where(cluster < 3, 1.0, 0.02)
    floor = covariance.pooled_design_floor
    over = {"jackknife": 0, "floored": 0}
    estimates, variances = [], []
    for _ in range(trials):
        y = rng.standard_t(3, len(J)) + 0.4 * rng.normal(size=patches)[cluster]
        theta, c = _cauchy_fit(J, y)
        r = y - J @ theta
        covariance.pooled_design_floor = lambda clustered, independent: clustered
        try:
            jackknife = sandwich(J, r, np.ones(len(J)), c, cluster, None)
        finally:
            covariance.pooled_design_floor = floor
        floored = sandwich(J, r, np.ones(len(J)), c, cluster, None)
        over["jackknife"] += int(abs(theta[2]) > 3 * np.sqrt(jackknife[2, 2]))
        over["floored"] += int(abs(theta[2]) > 3 * np.sqrt(floored[2, 2]))
        estimates.append(theta)
        variances.append(np.diag(floored))
    assert over["jackknife"] >= 3 * max(over["floored"], 1), over
    assert over["floored"] <= 0.025 * trials, over
    ratio = np.mean(variances, axis=0)[:2] / np.var(estimates, axis=0)[:2]
    assert np.all((ratio > 0.85) & (ratio < 1.6)), ratio
