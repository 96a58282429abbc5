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
from dataclasses import dataclass
from functools import partial

import numpy as np
from scipy import stats
from threadpoolctl import threadpool_limits

from ..._typing import FloatArray, Progress
from ...geometry.rotations import angles_from_axis, axis_from_angles
from ..errors import NotInitializableError
from ..initializer import InitializerError, cone_initial
from ..options import TracksOptions
from ..result import MotionResult, motion_fields, nearest_on_spin_axis, validation_fields
from ..sensor import SensorNoise
from ..tracks import MIN_FRAMES, Tracks
from ..validation import Similarity, similarity, validation_frame_count
from .fit import Fit, fit_model
from .search import swarm_search


@dataclass
class _Run:
    """What every step of one estimate shares."""

    T: float
    noise: SensorNoise
    n2: int
    opts: TracksOptions
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
    tracks: Tracks, options: TracksOptions | None = None, *, progress: Progress | None = None
) -> MotionResult:
    """Estimate the spin-precession motion of a target from feature tracks.

    Parameters
    ----------
    tracks : Tracks
        Validated observations (see :class:`tumblescan.tracks.Tracks`).
    options : TracksOptions, optional
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
        return _estimate(tracks, options or TracksOptions(), progress or _silent)


def _silent(stage: str, fraction: float) -> None:
    return None


def _estimate(tracks: Tracks, opts: TracksOptions, progress: Progress) -> MotionResult:
    started = time.perf_counter()
    T = opts.reference_time(float(tracks.t_s.min()), float(tracks.t_s.max()))
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
                raise NotInitializableError(
                    f"strategy 'lm' needs the closed-form start, which these tracks do not support ({exc}); "
                    "use strategy 'auto' or 'swarm'",
                    field="strategy",
                ) from None
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
