"""One model fitted to tracks by Levenberg-Marquardt, with outlier rejection and covariance.

Outliers: after each solve an observation whose whitened squared residual exceeds
``chi2.isf(1e-6, 3)`` times the robust noise scale ``median(e) / chi2.median(3)`` is
rejected (only the worst of each track per round, since a gross error drags its track's
other residuals along) and the fit repeated (at most ``MAX_REJECTION_ROUNDS`` times, never more than
``MAX_OUTLIER_FRACTION`` of the data). Rejected observations are counted, never hidden.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import stats
from scipy.optimize import least_squares

from ..._typing import FloatArray
from ...numerics.covariance import covariance
from ...target.motion import canonical_params, predict
from ..options import Objective
from ..sensor import SensorNoise
from ..tracks import Tracks
from ..validation import canonical_cov, embed
from .objective import ALL_FREE, SPIN_ONLY_FREE, MLProblem, PairwiseProblem, body_positions

LM_TOL = 1e-10  # Gauss-Newton is quadratic on noise-free data: this still reaches rounding level
# Gauss-Newton converges in a handful of steps here; more means a flat valley (a wrong model).
MAX_NFEV = 200
MAX_REJECTION_ROUNDS = 5
MAX_OUTLIER_FRACTION = 0.2
OUTLIER_TAIL = 1e-6
# Whitened residuals below this scale are rounding, not noise (noise-free data).
SCALE_FLOOR = 1e-12


@dataclass(frozen=True)
class Fit:
    """A fitted model: canonical 9-vector, unscaled 9x9 covariance, fit statistics.

    chi2: whitened sum of squares; dof: residuals minus unknowns; noise_scale:
    ``sqrt(chi2 / dof)`` (1 when the declared noise is right); rms_m: RMS position residual;
    keep: which observations were used (the rest were rejected as outliers).
    """

    x: FloatArray
    body_m: FloatArray
    free: tuple[int, ...]
    cov: FloatArray
    chi2: float
    dof: int
    noise_scale: float
    rms_m: float
    iterations: int
    keep: NDArray[np.bool_]

    @property
    def spin_only(self) -> bool:
        return self.free == SPIN_ONLY_FREE

    @property
    def outliers(self) -> int:
        return int((~self.keep).sum())

    def scaled_cov(self) -> FloatArray:
        return self.cov * self.noise_scale**2


def fit_model(
    tracks: Tracks,
    x0: FloatArray,
    *,
    spin_only: bool,
    objective: Objective,
    noise: SensorNoise,
    reference_time_s: float,
    gauge_point: FloatArray | None = None,
    keep: NDArray[np.bool_] | None = None,
    reject_outliers: bool = True,
) -> Fit:
    """Fit from start ``x0``; spin-only fixes ``w_p = 0`` and pins the centre on the axis
    nearest ``gauge_point`` (default: the features' centroid at the start)."""
    free = SPIN_ONLY_FREE if spin_only else ALL_FREE
    base = np.asarray(x0, dtype=float).copy()
    keep = np.ones(len(tracks), bool) if keep is None else keep.copy()
    if spin_only:
        base[3:6] = 0.0
        if gauge_point is None:
            gauge_point = body_positions(base, tracks.select(keep), reference_time_s).mean(axis=0)
    x, iterations = base, 0
    for _ in range(MAX_REJECTION_ROUNDS + 1):
        used = tracks.select(keep)
        x, nfev = _solve(used, x, free, objective, noise, reference_time_s, gauge_point)
        iterations += nfev
        problem = MLProblem(used, noise, reference_time_s, free=free, base=x, gauge_point=gauge_point)
        if objective == "ml":
            x, nfev = _lm_projected(problem, x)
            iterations += nfev
        z = problem.pack(x, problem.body_for(x))
        new_outliers = _outliers(problem, z) if reject_outliers else np.zeros(len(used), bool)
        if not new_outliers.any() or (~keep).sum() + new_outliers.sum() > MAX_OUTLIER_FRACTION * len(tracks):
            break
        idx = np.flatnonzero(keep)
        keep[idx[new_outliers]] = False
    return _finish(problem, z, free, keep, iterations)


def _solve(
    tracks: Tracks,
    x: FloatArray,
    free: tuple[int, ...],
    objective: Objective,
    noise: SensorNoise,
    reference_time_s: float,
    gauge_point: FloatArray | None,
) -> tuple[FloatArray, int]:
    """Pairwise objective: LM over the motion. ML: nothing here (solved jointly with P_j)."""
    if objective == "ml":
        return x, 0
    pair = PairwiseProblem(tracks, reference_time_s, free=free, base=x)
    out = x.copy()
    out[list(free)], nfev = _lm(pair.residuals, pair.jacobian, x[list(free)])
    return out, nfev


def _lm_projected(problem: MLProblem, x0: FloatArray) -> tuple[FloatArray, int]:
    """LM over the free motion parameters with every ``P_j`` projected out."""
    free = list(problem.free)
    x = problem.base.copy()
    x[free], nfev = _lm(problem.reduced_residuals, problem.reduced_jacobian, x0[free])
    return x, nfev


def _lm(
    residuals: Callable[[FloatArray], FloatArray], jacobian: Callable[[FloatArray], FloatArray], x0: FloatArray
) -> tuple[FloatArray, int]:
    """MINPACK Levenberg-Marquardt with this module's tolerances."""
    res = least_squares(
        residuals, x0, jac=jacobian, method="lm", xtol=LM_TOL, ftol=LM_TOL, gtol=LM_TOL, max_nfev=MAX_NFEV
    )
    return np.asarray(res.x, dtype=float), int(res.nfev)


def _outliers(problem: MLProblem, z: FloatArray) -> NDArray[np.bool_]:
    r = problem.residuals(z)[: 3 * len(problem.tracks)].reshape(-1, 3)
    e = np.sum(r**2, axis=1)
    scale = max(float(np.median(e)) / stats.chi2.median(3), SCALE_FLOOR)
    suspect = e > scale * stats.chi2.isf(OUTLIER_TAIL, 3)
    # A gross error drags its track's other observations along through P_j: blame only
    # the worst observation of each track per round, then refit.
    track = problem.tracks.track
    worst = np.full(problem.tracks.n_tracks, -1.0)
    np.maximum.at(worst, track, e)
    return np.asarray(suspect & (e == worst[track]))


def _finish(problem: MLProblem, z: FloatArray, free: tuple[int, ...], keep: NDArray[np.bool_], iterations: int) -> Fit:
    x, body = problem.unpack(z)
    r = problem.residuals(z)
    J = problem.jacobian(z)
    n_obs = len(problem.tracks)
    dof = max(len(r) - J.shape[1] - (problem.gauge_point is not None), 1)
    chi2 = float(r @ r)
    pos_err = _position_residuals(problem, z)
    cov9 = embed(covariance(J, len(free)), free)
    return Fit(
        x=canonical_params(x),
        body_m=body,
        free=free,
        cov=canonical_cov(x, cov9),
        chi2=chi2,
        dof=dof,
        noise_scale=float(np.sqrt(chi2 / dof)),
        rms_m=float(np.sqrt(np.mean(np.sum(pos_err**2, axis=1)))) if n_obs else 0.0,
        iterations=iterations,
        keep=keep,
    )


def _position_residuals(problem: MLProblem, z: FloatArray) -> FloatArray:
    x, body = problem.unpack(z)
    return np.asarray(predict(x, body[problem.tracks.track], problem.tau) - problem.tracks.xyz_m)
