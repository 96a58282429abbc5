"""Motion from dense line-scan frames, without feature tracks.

Recipe:
1. Register consecutive frames rigidly (FPFH + RANSAC + ICP).
2. Form a starting motion from the pairs, re-time each frame to its mean time with it,
   register again by ICP, and form the start again. The first start is the closed-form cone
   on the pairs whose rotation angle is near the median (every pair of one cone motion has
   the same angle).
3. Refine all 9 parameters by the dense continuous-time fit on every point (:mod:`tumblescan.dense`).
   If the fit is poor (residuals many times their model sigma, or frames unmatched), or the
   start could not be formed, start again from the cone most triplets of pairs agree with
   (:mod:`tumblescan.consensus`: a symmetric target can register onto a turned copy of
   itself, a fast one often does), and then from a particle swarm on a dense alignment cost
   (:mod:`tumblescan.dense_search`); keep the best fit.
4. Choose the model: keep spin-precession unless the precession rate is not significantly
   different from 0 (Wald test at ``significance``); then refit spin-only.
5. Validate (paper eq. 11): polish the motion on the first frames only and compare.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import stats
from threadpoolctl import threadpool_limits

from ..._typing import FloatArray, Progress
from ..errors import FramesUnusableError, NoSurfacesError
from ..frames import Frames
from ..initializer import InitialGuess
from ..options import FramesOptions
from ..result import MotionResult, motion_fields, nearest_on_spin_axis, validation_fields
from ..sensor import SensorNoise
from ..validation import Similarity, similarity, validation_frame_count
from .consensus import INLIER_RAD, pair_misfit, without_precession
from .degeneracy import degenerate_warnings, imprecision_warning
from .refine import DenseFit, refine_dense
from .registration import VOXEL_FRACTION, PairTransforms, extent_m, register_consecutive
from .search import OverlapCost, swarm_start
from .starts import Start, consensus_start, registration_start, retimed, same_basin, vote
from .surfels import DenseData, prepare

# Registration works on a thinned copy of each frame: this many points at most.
REGISTRATION_POINTS = 60_000
RETIME_PASSES = 2
SURFEL_FRACTION = 1 / 100
# A refined motion whose residuals are this many times their model sigma is wrong.
POOR_SCALE = 3.0
# Below this RMS residual (metres) the data count as noise-free: the paper's fixed threshold applies.
NOISE_FREE_RMS_M = 1e-7


@dataclass(frozen=True)
class _RegistrationPoints:
    """The thinned cloud registration works on: positions, offsets from ``T``, frames."""

    xyz_m: FloatArray
    tau_s: FloatArray
    frame: NDArray[np.int64]

    def split(self, xyz_m: FloatArray, n: int) -> list[FloatArray]:
        """``xyz_m`` (one row per point here) split into the ``n`` frames."""
        return [xyz_m[self.frame == f] for f in range(n)]


@dataclass(frozen=True)
class _Setup:
    """What every attempt at the motion shares: the dense data, the thinned cloud registration
    works on, the frames' mean times, the registration voxel and the caller's options."""

    data: DenseData
    reg: _RegistrationPoints
    mid: FloatArray
    voxel_m: float
    extent_m: float
    opts: FramesOptions
    noise: SensorNoise
    progress: Progress


@dataclass(frozen=True)
class _Solve:
    fit: DenseFit
    initial: InitialGuess
    pairs_used: int
    path: str


def estimate_from_frames(
    frames: Frames, options: FramesOptions | None = None, *, progress: Progress | None = None
) -> MotionResult:
    """Estimate the target's motion from dense line-scan frames (see the module docstring).

    Parameters
    ----------
    frames : Frames
        Points with per-point times, split into frames (:func:`tumblescan.assemble_frames`).
    options : FramesOptions, optional
        Reference time ``T`` (default: the first point's time), model choice, seed, sensor
        noise, validation frame count, significance and ``dense`` sampling settings.
    progress : callable, optional
        ``progress(stage, fraction)`` with stages ``registering``, ``initializing``,
        ``refining`` and ``validating``; it may raise to abandon the estimate.

    Returns
    -------
    MotionResult
        As for tracks; ``fit.source`` is ``frames`` and ``fit.frame_rms_m`` gives each
        frame's centroid-to-plane residual.
    """
    report = _never_backwards(progress or (lambda stage, fraction: None))
    with threadpool_limits(1, user_api="blas"):
        return _estimate(frames, options or FramesOptions(), report)


def _estimate(frames: Frames, opts: FramesOptions, progress: Progress) -> MotionResult:
    started = time.perf_counter()
    cloud = frames.cloud
    T = opts.reference_time(float(cloud.t_s.min()), float(cloud.t_s.max()))
    n_frames = frames.n_frames
    n2 = validation_frame_count(n_frames, opts.validation_frames)
    # 1. Thin every frame for registration; the dense fit uses every point.
    thin = _thin(frames, opts.seed)
    reg = _RegistrationPoints(cloud.xyz_m[thin], cloud.t_s[thin] - T, frames.frame[thin])
    per_frame = reg.split(reg.xyz_m, n_frames)
    extent = extent_m(per_frame)
    noise = opts.sensor or SensorNoise()
    data = prepare(
        cloud.xyz_m,
        cloud.t_s - T,
        frames.frame,
        surfel_m=opts.dense.surfel_m or extent * SURFEL_FRACTION,
        range_sigma_m=noise.range_sigma_m,
    )
    # 2-3. Register, initialize and refine on all frames, from up to three starts.
    progress("registering", 0.0)
    voxel = max(extent * VOXEL_FRACTION, 1e-3)
    global_pairs = register_consecutive(per_frame, voxel_m=voxel, seed=opts.seed)
    mid = _frame_taus(reg.tau_s, reg.frame, n_frames)
    setup = _Setup(data, reg, mid, voxel, extent, opts, noise, progress)
    best, warnings, attempts = _best_attempt(setup, global_pairs, n2)
    if data.spurious:
        warnings.append(
            f"{data.spurious} points ({100 * data.spurious / len(cloud):.1f} %) were left out of the fit as spurious "
            "returns (ranges far from the rest of their patch); they are rectified with the others"
        )
    main, fit, check = best.solve, best.fit, best.check
    still_poor = _poor_fit(fit)
    if still_poor is not None:
        warnings.append(f"no motion found fits the frames ({still_poor}): the estimate is unreliable")
    unmatched = np.flatnonzero(~np.isfinite(fit.frame_rms_m))
    if len(unmatched):
        warnings.append(
            f"frame(s) {', '.join(map(str, unmatched))} had no surface matched in another frame (an edge-on or "
            "featureless view): they constrain nothing and were left out of the fit and the check"
        )
    if still_poor is None:
        warnings += degenerate_warnings(data, fit, opts, noise)
    imprecise = imprecision_warning(fit.x, fit.cov, spin_only=fit.spin_only)
    if imprecise is not None:
        warnings.append(imprecise)
    if n2 >= n_frames:
        warnings.append(f"only {n_frames} frames: the two-frame-count check needs more")
    if check is not None and not check.passed:
        warnings.append(
            f"two-frame-count check failed: solutions from {n_frames} and {n2} frames differ by "
            f"{check.distance:.3g} (threshold {check.threshold:.3g}); treat the estimate with caution"
        )
    progress("estimated", 1.0)
    return _result(frames, fit, main, check, n2, T, warnings, attempts, time.perf_counter() - started)


@dataclass(frozen=True)
class _Attempt:
    """One start carried through: its solve, the fit after the model choice, the check on the
    first frames, and its warnings."""

    solve: _Solve
    fit: DenseFit
    check: Similarity | None
    warnings: list[str]

    def problem(self) -> str | None:
        """Why another start should be tried, or None when this one is sound. A frame without a
        match (an edge-on view) is noted, not a reason: it says nothing against the motion."""
        poor = _poor_fit(self.fit)
        if poor is not None:
            return poor
        if self.check is not None and not self.check.passed:
            return "the two-frame-count check failed"
        return None

    def flaws(self) -> tuple[bool, bool, int, float]:
        """Order of preference: a fit that is not poor, a check that passed, fewer unmatched
        frames, smaller residuals."""
        failed = self.check is not None and not self.check.passed
        unmatched = int(np.sum(~np.isfinite(self.fit.frame_rms_m)))
        return (_poor_fit(self.fit) is not None, failed, unmatched, self.fit.scale)


def _best_attempt(setup: _Setup, global_pairs: PairTransforms, n2: int) -> tuple[_Attempt, list[str], int]:
    """The vote on rotation angles, then, if its motion fits poorly or fails the check, the
    consensus over triplets of pairs, then the swarm on the dense cost: the first sound attempt,
    or the least flawed one, its warnings and how many starts were made."""
    mid, seed = setup.mid, setup.opts.seed
    starts = (
        (lambda: vote(global_pairs, mid), "registration+cone+dense"),
        (lambda: consensus_start(global_pairs, mid, seed), "registration+consensus+dense"),
        (lambda: _swarm(setup, global_pairs), "registration+swarm+dense"),
    )
    best: _Attempt | None = None
    tried: list[str] = []
    made = 0
    confirmed = False  # a second start led where a motion that failed the check only ended
    for begin, path in starts:
        if confirmed:
            # Two registration starts lead to one motion that fits the points: the failed check
            # says the first frames alone do not pin it down (slow precession, mostly), not that
            # the basin is wrong. Further starts after such a failure found a sound motion in none
            # of 20 cases on the real-shapes bench (two runs of 72) and cost 10-40 s each.
            break
        made += 1
        if tried:
            setup.progress("initializing", 0.05)
        attempt_warnings: list[str] = []
        try:
            start = begin()
            if best is not None and isinstance(start, Start) and same_basin(start.guess.x, best.fit.x):
                # Refined, it would end where the last one did (and fail the same way): 10-40 s
                # of registration and refinement for nothing.
                tried.append(f"{path}: starts where the motion above ended, not refined again")
                confirmed = _check_only(best)
                continue
            solve = _solve(setup, global_pairs, start, attempt_warnings, path=path)
        except NoSurfacesError:
            raise
        except FramesUnusableError as exc:
            tried.append(f"{path}: {exc}")
            continue
        attempt = _judged(setup, solve, n2, attempt_warnings)
        ended_alike = best is not None and same_basin(attempt.fit.x, best.fit.x)
        confirmed = ended_alike and _check_only(attempt)
        if best is None or attempt.flaws() < best.flaws():
            best = attempt
        problem = attempt.problem()
        if problem is None:
            break
        tried.append(f"{path}: {problem}" + (" (it ended where the motion above did)" if ended_alike else ""))
    if best is None:
        raise FramesUnusableError("the motion could not be estimated: " + "; ".join(tried), field="file")
    kept = list(best.warnings)
    if tried:
        outcome = "no start was sound" if best.problem() else "the motion comes from " + best.solve.path
        kept.append(f"{len(tried)} start(s) tried before ({'; '.join(tried)}); {outcome}")
    return best, kept, made


def _check_only(attempt: _Attempt | None) -> bool:
    """Whether the attempt's motion fits the points and failed the check only."""
    return attempt is not None and _poor_fit(attempt.fit) is None and attempt.problem() is not None


def _judged(setup: _Setup, solve: _Solve, n2: int, warnings: list[str]) -> _Attempt:
    """The model choice and the two-frame-count check on one solve."""
    fit, opts = solve.fit, setup.opts
    # 4. Model choice.
    if opts.model == "auto" and _precession_insignificant(fit, opts, warnings):
        setup.progress("refining", 0.66)
        fit = refine_dense(
            setup.data, solve.initial.x_spin_only, spin_only=True, config=opts.dense, noise=setup.noise, seed=opts.seed
        )
    # 5. Validate: do the first n2 frames alone support the motion?
    check = None
    if n2 < setup.data.n_frames:
        setup.progress("validating", 0.7)
        check = _validate(setup, n2, fit)
    return _Attempt(solve, fit, check, warnings)


def _never_backwards(progress: Progress) -> Progress:
    """``progress`` with the fraction held at its maximum so far: the swarm's fallback repeats
    the registering and refining stages, and a progress bar should not run back."""
    most = 0.0

    def report(stage: str, fraction: float) -> None:
        nonlocal most
        most = max(most, fraction)
        progress(stage, most)

    return report


def _thin(frames: Frames, seed: int) -> NDArray[np.int64]:
    """At most ``REGISTRATION_POINTS`` points per frame, chosen at random (seeded)."""
    rng = np.random.default_rng(seed)
    keep = []
    order = np.argsort(frames.frame, kind="stable")
    bounds = np.searchsorted(frames.frame[order], np.arange(frames.n_frames + 1))
    for f in range(frames.n_frames):
        idx = order[bounds[f] : bounds[f + 1]]
        if len(idx) > REGISTRATION_POINTS:
            idx = rng.choice(idx, REGISTRATION_POINTS, replace=False)
        keep.append(idx)
    return np.sort(np.concatenate(keep))


def _frame_taus(tau: FloatArray, frame: NDArray[np.int64], n_frames: int) -> FloatArray:
    return np.asarray(np.bincount(frame, weights=tau, minlength=n_frames) / np.bincount(frame, minlength=n_frames))


def _solve(setup: _Setup, pairs: PairTransforms, start: Start, warnings: list[str], *, path: str) -> _Solve:
    """From a motion most pairs agree with: re-time and register again, refine on every point."""
    reg, mid, opts, progress = setup.reg, setup.mid, setup.opts, setup.progress
    # Re-timed registration passes: the in-frame smear no longer biases the rotations, and pairs
    # registered onto a turned copy of the target restart from the predicted transform.
    for p in range(RETIME_PASSES):
        progress("registering", 0.1 * (p + 1) / RETIME_PASSES)
        xyz = retimed(reg.xyz_m, reg.tau_s, reg.frame, mid, pairs, start)
        initial = registration_start(pairs, start, mid)
        pairs = register_consecutive(
            reg.split(xyz, setup.data.n_frames), voxel_m=setup.voxel_m, initial=initial, seed=opts.seed
        )
        start = vote(pairs, mid) if start.voted else consensus_start(pairs, mid, opts.seed)
    progress("initializing", 0.1)
    used = int(start.inliers.sum())
    if used < len(start.inliers):
        warnings.append(
            f"{len(start.inliers) - used} of {len(start.inliers)} frame pairs registered inconsistently with the "
            "others (a symmetric target can match a turned copy of itself); the initial motion used the others"
        )
    guess = start.guess
    progress("refining", 0.15)

    def on_step(step: int, total: int) -> None:
        progress("refining", 0.15 + 0.5 * step / total)

    spin_only = opts.model == "spin-only"
    fit = refine_dense(
        setup.data,
        guess.x_spin_only if spin_only else guess.x,
        spin_only=spin_only,
        config=opts.dense,
        noise=setup.noise,
        seed=opts.seed,
        on_iteration=on_step,
    )
    if fit.residuals == 0:
        raise NoSurfacesError(
            "no planar patch of one frame could be matched in another (are the frames of one rigid target, and "
            "is the declared range noise right?)",
            field="file",
        )
    return _Solve(fit, guess, used, path)


def _poor_fit(fit: DenseFit) -> str | None:
    """Why the refined motion cannot be right, or None: residuals many times their model sigma."""
    if not fit.scale <= POOR_SCALE:
        return f"residuals {fit.scale:.1f} times their expected size"
    return None


def _swarm(setup: _Setup, pairs: PairTransforms) -> Start:
    """The swarm's start (:mod:`tumblescan.dense_search`) and the pairs that agree with it."""
    reg, mid, extent, seed = setup.reg, setup.mid, setup.extent_m, setup.opts.seed
    cost = OverlapCost.for_extent(reg.xyz_m, reg.tau_s, reg.frame, setup.data.n_frames, extent_m=extent, seed=seed)
    try:
        found = swarm_start(pairs.R, pairs.t, mid, cost, extent, seed=seed)
    except ValueError as exc:
        raise FramesUnusableError(f"the swarm found no start: {exc}", field="file") from None
    return Start(
        guess=InitialGuess(x=found.x, x_spin_only=without_precession(found.x), cone_collapsed=False, passes=1),
        inliers=pair_misfit(found.x, pairs.R, mid[:-1], mid[1:]) < INLIER_RAD,
    )


def _precession_insignificant(fit: DenseFit, opts: FramesOptions, warnings: list[str]) -> bool:
    sd = float(np.sqrt(fit.cov[5, 5]))
    z = abs(float(fit.x[5])) / sd if sd > 0 else np.inf
    p_value = float(2 * stats.norm.sf(z))
    if p_value < opts.significance:
        return False
    warnings.append(
        f"no significant precession (Wald test p={p_value:.3g}): reporting the spin-only model; the precession "
        "axis and the centre's position along the spin axis are unobservable"
    )
    return True


def _validate(setup: _Setup, n2: int, fit: DenseFit) -> Similarity:
    """Refine again on the first ``n2`` frames only, from the motion found on all of them: do
    those frames alone support it? (A start from their own registrations would repeat the
    initializer's work on a shorter, weaker baseline; that start is tested by the main solve.)"""

    def on_step(step: int, total: int) -> None:
        setup.progress("validating", 0.7 + 0.28 * step / total)

    opts = setup.opts
    sub = refine_dense(
        setup.data.first_frames(n2),
        fit.x,
        spin_only=fit.spin_only,
        config=opts.dense,
        noise=setup.noise,
        seed=opts.seed + 1,
        converged=True,
        gauge_point=fit.x[6:9] if fit.spin_only else None,
        on_iteration=on_step,
    )
    noise_scale = 1.0 if fit.rms_m > NOISE_FREE_RMS_M else 0.0
    return similarity(fit.x, sub.x, sub.cov, free=fit.free, noise_scale=noise_scale, alpha=opts.significance)


def _result(
    frames: Frames,
    fit: DenseFit,
    main: _Solve,
    check: Similarity | None,
    n2: int,
    T: float,
    warnings: list[str],
    attempts: int,
    elapsed_s: float,
) -> MotionResult:
    x = fit.x
    center = x[6:9]
    if fit.spin_only:
        center = nearest_on_spin_axis(x, frames.cloud.xyz_m.mean(axis=0))
    frame_rms = [None if not np.isfinite(v) else float(v) for v in fit.frame_rms_m]
    return MotionResult.model_validate(
        {
            **motion_fields(x, fit.cov, spin_only=fit.spin_only, center_m=center, reference_time_s=T),
            "fit": {
                "rms_residual_m": fit.rms_m,
                "observations": len(frames.cloud),
                "tracks": 0,
                "frames": frames.n_frames,
                "outliers": 0,
                "source": "frames",
                "points_used": fit.points,
                "frame_rms_m": frame_rms,
            },
            "validation": validation_fields(check, frames.n_frames, n2),
            "solver": {
                "path": f"{main.path} ({main.pairs_used} frame pairs)",
                "iterations": fit.iterations,
                "attempts": attempts,
                "elapsed_s": elapsed_s,
            },
            "warnings": warnings,
        }
    )
