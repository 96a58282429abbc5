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
from scipy.spatial.transform import Rotation
from threadpoolctl import threadpool_limits

from ..._typing import FloatArray, Progress
from ...geometry.rotations import rotate
from ...target.motion import rotation_matrices
from ..errors import FramesUnusableError, NoSurfacesError
from ..frames import Frames
from ..initializer import InitialGuess, InitializerError, center_from_transforms, motion_from_transforms
from ..options import FramesOptions
from ..result import MotionResult, motion_fields, nearest_on_spin_axis, validation_fields
from ..sensor import SensorNoise
from ..validation import Similarity, similarity, validation_frame_count
from .consensus import INLIER_RAD, cone_consensus, pair_misfit, without_precession
from .refine import DenseFit, refine_dense
from .registration import VOXEL_FRACTION, PairTransforms, consistent_pairs, extent_m, register_consecutive
from .search import OverlapCost, swarm_start
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
    T = float(cloud.t_s.min()) if opts.reference_time_s is None else opts.reference_time_s
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
    main, warnings = _best_attempt(setup, global_pairs)
    if data.spurious:
        warnings.append(
            f"{data.spurious} points ({100 * data.spurious / len(cloud):.1f} %) were left out of the fit as spurious "
            "returns (ranges far from the rest of their patch); they are rectified with the others"
        )
    still_poor = _poor_fit(main.fit)
    if still_poor is not None:
        warnings.append(f"no motion found fits the frames ({still_poor}): the estimate is unreliable")
    fit = main.fit
    # 4. Model choice.
    if opts.model == "auto" and _precession_insignificant(fit, opts, warnings):
        progress("refining", 0.66)
        fit = refine_dense(
            data, main.initial.x_spin_only, spin_only=True, config=opts.dense, noise=setup.noise, seed=opts.seed
        )
    # 5. Validate: do the first n2 frames alone support the motion?
    check: Similarity | None = None
    if n2 < n_frames:
        progress("validating", 0.7)
        check = _validate(setup, n2, fit)
    else:
        warnings.append(f"only {n_frames} frames: the two-frame-count check needs more")
    if check is not None and not check.passed:
        warnings.append(
            f"two-frame-count check failed: solutions from {n_frames} and {n2} frames differ by "
            f"{check.distance:.3g} (threshold {check.threshold:.3g}); treat the estimate with caution"
        )
    progress("estimated", 1.0)
    return _result(frames, fit, main, check, n2, T, warnings, time.perf_counter() - started)


def _best_attempt(setup: _Setup, global_pairs: PairTransforms) -> tuple[_Solve, list[str]]:
    """The vote on rotation angles, then, if its motion fits poorly, the consensus over triplets
    of pairs, then the swarm on the dense cost: the best fit (smallest residual scale) and its
    warnings."""
    mid, seed = setup.mid, setup.opts.seed
    attempts = (
        (lambda: _vote(global_pairs, mid), "registration+cone+dense"),
        (lambda: _consensus(global_pairs, mid, seed), "registration+consensus+dense"),
        (lambda: _swarm(setup, global_pairs), "registration+swarm+dense"),
    )
    main: _Solve | None = None
    kept: list[str] = []
    tried: list[str] = []
    for begin, path in attempts:
        if tried:
            setup.progress("initializing", 0.05)
        attempt_warnings: list[str] = []
        try:
            alt = _solve(setup, global_pairs, begin(), attempt_warnings, path=path)
        except NoSurfacesError:
            raise
        except FramesUnusableError as exc:
            tried.append(f"{path}: {exc}")
            continue
        if main is None or alt.fit.scale < main.fit.scale:
            main, kept = alt, attempt_warnings
        poor = _poor_fit(alt.fit)
        if poor is None:
            break
        tried.append(f"{path}: {poor}")
    if main is None:
        raise FramesUnusableError("the motion could not be estimated: " + "; ".join(tried), field="file")
    if tried and main.path != attempts[0][1]:
        kept = [*kept, "the first start failed (" + "; ".join(tried) + f"); the motion comes from {main.path}"]
    return main, kept


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


def _retimed(
    xyz: FloatArray, tau: FloatArray, frame: NDArray[np.int64], mid: FloatArray, pairs: PairTransforms, start: _Start
) -> FloatArray:
    """Points moved to their frame's mean time, rotating at the mean angular velocity of the pairs
    just before and after each frame. Voted start: the inlier pairs only (their median for a
    frame with none), about their common fixed point. Otherwise: registered where the pair
    agrees with the hypothesis, predicted by it where not, about the hypothesis's centre."""
    ok = start.inliers
    R = pairs.R if start.voted else np.where(ok[:, None, None], pairs.R, _predicted(start.guess.x, mid).R)
    rotvec = Rotation.from_matrix(R).as_rotvec() / np.diff(mid)[:, None]
    omega = np.empty((len(mid), 3))
    for f in range(len(mid)):
        near = [k for k in (f - 1, f) if 0 <= k < len(rotvec) and (ok[k] or not start.voted)]
        omega[f] = rotvec[near].mean(axis=0) if near else np.median(rotvec[ok], axis=0)
    center = center_from_transforms(pairs.R[ok], pairs.t[ok]) if start.voted else start.guess.x[6:9]
    w = omega[frame]
    rate = np.linalg.norm(w, axis=1)
    axis = w / np.maximum(rate, 1e-300)[:, None]
    return np.asarray(center + rotate(axis, rate * (mid[frame] - tau), xyz - center), dtype=float)


def _predicted(x: FloatArray, mid: FloatArray) -> PairTransforms:
    """The transforms between consecutive frames' mean times that motion ``x`` predicts."""
    R = rotation_matrices(x, mid)
    Q = R[1:] @ np.swapaxes(R[:-1], 1, 2)
    center = x[6:9]
    n = len(Q)
    return PairTransforms(Q, center - Q @ center, np.zeros(n), np.zeros(n))


def _registration_start(pairs: PairTransforms, start: _Start, mid: FloatArray) -> PairTransforms:
    """ICP starts: the registered transform where the pair agrees with the hypothesis (or for
    every pair after a vote), the predicted one where it does not (a pair registered onto a
    turned copy gets another chance)."""
    if start.voted:
        return pairs
    predicted = _predicted(start.guess.x, mid)
    keep = start.inliers
    return PairTransforms(
        np.where(keep[:, None, None], pairs.R, predicted.R),
        np.where(keep[:, None], pairs.t, predicted.t),
        pairs.fitness,
        pairs.rmse_m,
    )


@dataclass(frozen=True)
class _Start:
    """A starting motion and its inlier pairs; ``voted``: chosen by the vote on rotation angles."""

    guess: InitialGuess
    inliers: NDArray[np.bool_]
    voted: bool = False


def _vote(pairs: PairTransforms, mid: FloatArray) -> _Start:
    """The cone on the pairs whose rotation angle is near the median (every pair of the cone
    has the same angle): the path measured on the paper's grid."""
    ok = consistent_pairs(pairs)
    k = np.flatnonzero(ok)
    if len(k) < 3:
        raise FramesUnusableError(
            f"only {len(k)} of {len(ok)} consecutive frame pairs could be registered consistently; the initial "
            "motion needs 3 (do the frames overlap, and is the target rotating less than ~90 degrees per frame?)",
            field="file",
        )
    try:
        guess = motion_from_transforms(pairs.R[k], pairs.t[k], mid[k], mid[k + 1], 0.0)
    except InitializerError as exc:
        raise FramesUnusableError(f"the initial motion could not be formed: {exc}", field="file") from None
    return _Start(guess=guess, inliers=ok, voted=True)


def _consensus(pairs: PairTransforms, mid: FloatArray, seed: int) -> _Start:
    try:
        found = cone_consensus(pairs.R, pairs.t, mid[:-1], mid[1:], 0.0, seed=seed)
        return _Start(guess=found.guess, inliers=found.inliers)
    except InitializerError as exc:
        raise FramesUnusableError(
            f"the initial motion could not be formed from the registered frame pairs: {exc} (do the frames "
            "overlap, and is the target rotating less than ~90 degrees per frame?)",
            field="file",
        ) from None


def _solve(setup: _Setup, pairs: PairTransforms, start: _Start, warnings: list[str], *, path: str) -> _Solve:
    """From a motion most pairs agree with: re-time and register again, refine on every point."""
    reg, mid, opts, progress = setup.reg, setup.mid, setup.opts, setup.progress
    # Re-timed registration passes: the in-frame smear no longer biases the rotations, and pairs
    # registered onto a turned copy of the target restart from the predicted transform.
    for p in range(RETIME_PASSES):
        progress("registering", 0.1 * (p + 1) / RETIME_PASSES)
        xyz = _retimed(reg.xyz_m, reg.tau_s, reg.frame, mid, pairs, start)
        initial = _registration_start(pairs, start, mid)
        pairs = register_consecutive(
            reg.split(xyz, setup.data.n_frames), voxel_m=setup.voxel_m, initial=initial, seed=opts.seed
        )
        start = _vote(pairs, mid) if start.voted else _consensus(pairs, mid, opts.seed)
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
    """Why the refined motion cannot be right, or None: residuals many times their model sigma,
    or frames left without a single match."""
    if not fit.scale <= POOR_SCALE:
        return f"residuals {fit.scale:.1f} times their expected size"
    unmatched = int(np.sum(~np.isfinite(fit.frame_rms_m)))
    if unmatched:
        return f"{unmatched} of {len(fit.frame_rms_m)} frames without a match"
    return None


def _swarm(setup: _Setup, pairs: PairTransforms) -> _Start:
    """The swarm's start (:mod:`tumblescan.dense_search`) and the pairs that agree with it."""
    reg, mid, extent, seed = setup.reg, setup.mid, setup.extent_m, setup.opts.seed
    cost = OverlapCost.for_extent(reg.xyz_m, reg.tau_s, reg.frame, setup.data.n_frames, extent_m=extent, seed=seed)
    try:
        found = swarm_start(pairs.R, pairs.t, mid, cost, extent, seed=seed)
    except ValueError as exc:
        raise FramesUnusableError(f"the swarm found no start: {exc}", field="file") from None
    return _Start(
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
                "attempts": 1,
                "elapsed_s": elapsed_s,
            },
            "warnings": warnings,
        }
    )
