"""The hybrid motion estimator over feature tracks (method.md sections 3-5, paper Fig. 2).

Recipe:
1. Start: the closed-form cone initializer (``auto``/``lm``) or the particle swarm (``swarm``,
   or ``auto`` when the initializer cannot run).
2. Refine the spin-precession model by Levenberg-Marquardt, rejecting outliers.
3. Choose the model: fit spin-only as well and keep it unless the extra precession
   parameters reduce the fit significantly (F-test at ``significance``).
4. Validate (paper eq. 11): solve again from scratch with fewer frames and compare; on
   failure ``auto``/``swarm`` retry the swarm path, at most ``max_attempts`` in all.
5. Report the canonical motion with 1-sigma uncertainties from the fit's covariance.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field
from scipy import stats
from threadpoolctl import threadpool_limits

from .dense import DenseConfig
from .errors import InvalidOptionError
from .fit import Fit, Objective, fit_model
from .initializer import InitializerError, cone_initial
from .motion import angles_from_axis, axis_from_angles
from .result import MotionResult
from .sensor import SensorNoise
from .swarm import SwarmConfig, swarm_search
from .tracks import MIN_FRAMES, Tracks
from .uncertainty import Similarity, axis_sigma_rad, similarity

FloatArray = NDArray[np.float64]
Progress = Callable[[str, float], None]
Strategy = Literal["auto", "lm", "swarm"]
ModelChoice = Literal["auto", "spin-precession", "spin-only"]


class EstimateOptions(BaseModel):
    """Options of :func:`estimate_motion`; unknown names are rejected."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    strategy: Strategy = Field("auto", description="auto: initializer if it validates, else swarm; then LM")
    objective: Objective = Field("ml", description="ml (maximum likelihood) or pairwise (paper eq. 10)")
    model: ModelChoice = Field("auto", description="auto chooses spin-only vs spin-precession by an F-test")
    reference_time_s: float | None = Field(None, allow_inf_nan=False, description="default: first observation")
    seed: int = Field(0, ge=0, le=2**63 - 1)
    sensor: SensorNoise | None = Field(None, description="overrides the noise declared with the tracks")
    swarm: SwarmConfig = SwarmConfig()
    max_attempts: int = Field(3, ge=1, le=20)
    validation_frames: int | None = Field(None, ge=MIN_FRAMES, description="frames in the second solve")
    significance: float = Field(1e-3, gt=0, lt=0.5, description="level of the model and similarity tests")
    reject_outliers: bool = True
    frame_period_s: float | None = Field(
        None, gt=0, allow_inf_nan=False, description="frames input without frame indices: the scanner's frame period"
    )
    dense: DenseConfig = Field(DenseConfig(), description="frames input: sampling and iterations of the dense fit")


@dataclass
class _Run:
    """What every step of one estimate shares."""

    T: float
    noise: SensorNoise
    n2: int
    opts: EstimateOptions
    rng: np.random.Generator
    progress: Progress

    @property
    def allow_fallback(self) -> bool:
        return self.opts.strategy == "auto"


@dataclass
class _Solution:
    fit: Fit
    path: str
    check: Similarity | None
    n2: int
    warnings: list[str]


def estimate_motion(
    tracks: Tracks, options: EstimateOptions | None = None, *, progress: Progress | None = None
) -> MotionResult:
    """Estimate the spin-precession motion of a target from feature tracks.

    Parameters
    ----------
    tracks : Tracks
        Validated observations (see :class:`tumblescan.tracks.Tracks`).
    options : EstimateOptions, optional
        Strategy, objective, model choice, reference time ``T`` (s), seed and noise.
    progress : callable, optional
        ``progress(stage, fraction)`` at each step; it may raise to abandon the estimate.

    Returns
    -------
    MotionResult
        The canonical motion at ``T`` with 1-sigma uncertainties, fit statistics, the
        two-frame-count validation and warnings for anything unobservable or doubtful.
    """
    # Every matrix here is small: multithreaded BLAS only adds synchronization (measured
    # 1.3x slower on 2 cores), and it would oversubscribe a worker pool.
    with threadpool_limits(1, user_api="blas"):
        return _estimate(tracks, options or EstimateOptions(), progress or _silent)


def _silent(stage: str, fraction: float) -> None:
    return None


def _estimate(tracks: Tracks, opts: EstimateOptions, progress: Progress) -> MotionResult:
    started = time.perf_counter()
    T = float(tracks.t_s.min()) if opts.reference_time_s is None else opts.reference_time_s
    noise = opts.sensor or tracks.sensor or SensorNoise()
    n2 = validation_frame_count(tracks.n_frames, opts.validation_frames)
    run = _Run(T, noise, n2, opts, np.random.default_rng(opts.seed), progress)
    best: _Solution | None = None
    attempts = 0
    for attempt in range(opts.max_attempts):
        attempts += 1
        path = "swarm" if opts.strategy == "swarm" or attempt > 0 else "initializer"
        progress(f"estimating (attempt {attempt + 1})", attempt / opts.max_attempts)
        sol = _attempt(tracks, run, path)
        best = sol if best is None or _better(sol, best) else best
        if (sol.check is None or sol.check.passed) or opts.strategy == "lm":
            break
    assert best is not None
    progress("estimated", 1.0)
    if best.check is not None and not best.check.passed:
        best.warnings.append(
            f"two-frame-count check failed after {attempts} attempt(s): solutions from {tracks.n_frames} and "
            f"{n2} frames differ by {best.check.distance:.3g} (threshold {best.check.threshold:.3g}); "
            "returning the best fit, treat it with caution"
        )
    return _result(tracks, best, T, attempts, time.perf_counter() - started)


def validation_frame_count(n_frames: int, requested: int | None) -> int:
    if requested is not None:
        if requested >= n_frames:
            raise InvalidOptionError(
                f"validation_frames={requested} must be fewer than the {n_frames} frames given",
                field="options.validation_frames",
            )
        return requested
    return max(MIN_FRAMES, n_frames - max(1, round(n_frames / 4)))


def _better(a: _Solution, b: _Solution) -> bool:
    a_ok = a.check is None or a.check.passed
    b_ok = b.check is None or b.check.passed
    return (a_ok and not b_ok) or (a_ok == b_ok and a.fit.chi2 < b.fit.chi2)


def _attempt(tracks: Tracks, run: _Run, path: str) -> _Solution:
    warnings: list[str] = []
    # 1-2. Start and refine the general model.
    opts, n2 = run.opts, run.n2
    x0, x0_spin, taken = _start(tracks, run, path, warnings)
    fit = partial(fit_model, objective=opts.objective, noise=run.noise, reference_time_s=run.T)
    full = fit(tracks, x0, spin_only=False, reject_outliers=opts.reject_outliers)
    # 3. Model choice, on the observations the general model kept.
    chosen = full
    if opts.model != "spin-precession":
        spin_x0 = x0_spin if x0_spin is not None else _spin_start(full.x)
        spin = fit(tracks, spin_x0, spin_only=True, keep=full.keep, reject_outliers=False)
        if opts.model == "spin-only" or _prefer_spin_only(full, spin, opts.significance, warnings):
            chosen = spin
    # 4. Validate with the first n2 frames, solved from scratch along the same path.
    if n2 >= tracks.n_frames:
        warnings.append(f"only {tracks.n_frames} frames: the two-frame-count check needs {MIN_FRAMES + 1} or more")
        return _Solution(chosen, taken, None, n2, warnings)
    sub_tracks = tracks.first_frames(n2)
    try:
        s0, s0_spin, _ = _start(sub_tracks, run, path, [])
        gauge = chosen.body_m.mean(axis=0) if chosen.spin_only else None
        start = (s0_spin if s0_spin is not None else _spin_start(s0)) if chosen.spin_only else s0
        sub = fit(
            sub_tracks, start, spin_only=chosen.spin_only, gauge_point=gauge, reject_outliers=opts.reject_outliers
        )
        check = similarity(
            chosen.x, sub.x, sub.cov, free=chosen.free, noise_scale=chosen.noise_scale, alpha=opts.significance
        )
    except InitializerError as exc:
        check = Similarity(False, float("inf"), float("nan"), "skipped")
        warnings.append(f"second solve with {n2} frames could not start: {exc}")
    return _Solution(chosen, taken, check, n2, warnings)


def _start(tracks: Tracks, run: _Run, path: str, warnings: list[str]) -> tuple[FloatArray, FloatArray | None, str]:
    """Starting 9-vectors for the full and the spin-only model, and the path taken."""
    if path == "initializer":
        try:
            guess = cone_initial(tracks, run.T)
            return guess.x, guess.x_spin_only, "initializer+lm"
        except InitializerError as exc:
            if not run.allow_fallback:
                raise
            warnings.append(f"closed-form initializer unavailable ({exc}); used the swarm")
    cfg = run.opts.swarm
    found = swarm_search(
        tracks, run.T, cfg, run.rng, on_iteration=lambda i: run.progress("swarm search", (i + 1) / cfg.iterations)
    )
    return found.x, None, f"swarm({cfg.variant})+lm"


def _spin_start(x: FloatArray) -> FloatArray:
    """Spin-only start from a full 9-vector: the mean angular velocity ``w_s l_s + w_p l_p``."""
    omega = x[2] * axis_from_angles(x[0], x[1]) + x[5] * axis_from_angles(x[3], x[4])
    a, b = angles_from_axis(omega) if np.linalg.norm(omega) > 0 else (x[0], x[1])
    return np.array([a, b, float(np.linalg.norm(omega)), 0.0, 0.0, 0.0, *x[6:9]])


def _prefer_spin_only(full: Fit, spin: Fit, alpha: float, warnings: list[str]) -> bool:
    """F-test of spin-only (5 effective parameters) inside spin-precession (9)."""
    extra = 4
    num = max(spin.chi2 - full.chi2, 0.0) / extra
    den = max(full.chi2 / full.dof, 1e-12)
    p_value = float(stats.f.sf(num / den, extra, full.dof))
    if p_value < alpha:
        return False
    warnings.append(
        f"no significant precession (F-test p={p_value:.3g}): reporting the spin-only model; the precession "
        "axis and the centre's position along the spin axis are unobservable (a spin axis parallel to the "
        "precession axis looks the same, and then the spin rate reported is the sum of both rates)"
    )
    return True


def _result(tracks: Tracks, sol: _Solution, T: float, attempts: int, elapsed_s: float) -> MotionResult:
    fit = sol.fit
    x = fit.x
    center = x[6:9]
    if fit.spin_only:
        # The centre reported is the point of the spin axis nearest the features' centroid.
        center = nearest_on_spin_axis(x, fit.body_m.mean(axis=0))
    warnings = list(sol.warnings)
    if fit.outliers:
        warnings.append(f"{fit.outliers} observation(s) rejected as outliers (counted in fit.observations)")
    return MotionResult.model_validate(
        {
            **motion_fields(x, fit.scaled_cov(), spin_only=fit.spin_only, center_m=center, reference_time_s=T),
            "fit": {
                "rms_residual_m": fit.rms_m,
                "observations": len(tracks),
                "tracks": tracks.n_tracks,
                "frames": tracks.n_frames,
                "outliers": fit.outliers,
            },
            "validation": validation_fields(sol.check, tracks.n_frames, sol.n2),
            "solver": {"path": sol.path, "iterations": fit.iterations, "attempts": attempts, "elapsed_s": elapsed_s},
            "warnings": warnings,
        }
    )


def nearest_on_spin_axis(x: FloatArray, point_m: FloatArray) -> FloatArray:
    """The point of the spin axis (through ``x``'s centre) nearest ``point_m``."""
    l_s = axis_from_angles(x[0], x[1])
    return np.asarray(x[6:9] + l_s * float(l_s @ (point_m - x[6:9])), dtype=float)


def motion_fields(
    x: FloatArray, cov: FloatArray, *, spin_only: bool, center_m: FloatArray, reference_time_s: float
) -> dict[str, Any]:
    """The motion part of a :class:`MotionResult` from a canonical 9-vector and its covariance."""
    deg = np.degrees
    l_s = axis_from_angles(x[0], x[1])
    l_p = None if spin_only else axis_from_angles(x[3], x[4])
    return {
        "model": "spin-only" if spin_only else "spin-precession",
        "reference_time_s": reference_time_s,
        "spin": {"axis": l_s.tolist(), "alpha_deg": deg(x[0]), "beta_deg": deg(x[1]), "rate_deg_s": deg(x[2])},
        "precession": {
            "axis": None if l_p is None else l_p.tolist(),
            "alpha_deg": None if spin_only else deg(x[3]),
            "beta_deg": None if spin_only else deg(x[4]),
            "rate_deg_s": 0.0 if spin_only else deg(x[5]),
            "center_m": np.asarray(center_m).tolist(),
        },
        "nutation_angle_deg": None if l_p is None else deg(np.arccos(np.clip(l_s @ l_p, -1, 1))),
        "uncertainty": {
            "spin_axis_deg": deg(axis_sigma_rad(x, cov, 0, 1)),
            "spin_rate_deg_s": deg(np.sqrt(cov[2, 2])),
            "precession_axis_deg": None if spin_only else deg(axis_sigma_rad(x, cov, 3, 4)),
            "precession_rate_deg_s": deg(np.sqrt(cov[5, 5])),
            "center_m": np.sqrt(np.diag(cov)[6:9]).tolist(),
        },
    }


def validation_fields(check: Similarity | None, n_frames: int, n2: int) -> dict[str, Any]:
    return {
        "passed": bool(check is not None and check.passed),
        "frames": (n_frames, n2),
        "distance": None if check is None or not np.isfinite(check.distance) else check.distance,
        "threshold": None if check is None or not np.isfinite(check.threshold) else check.threshold,
        "test": "skipped" if check is None else check.test,
    }
