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

import numpy as np
from numpy.typing import NDArray
from threadpoolctl import threadpool_limits

from ..._typing import FloatArray, Progress
from ..errors import NoSurfacesError
from ..frames import Frames
from ..options import FramesOptions
from ..result import MotionResult, motion_fields, nearest_on_spin_axis, validation_fields
from ..sensor import SensorNoise
from ..validation import Similarity, validation_frame_count
from .attempts import RegistrationPoints, Setup, Solve, best_attempt, poor_fit
from .data import DenseData, prepare
from .degeneracy import degenerate_warnings, imprecision_warning
from .faces import MIN_SURFEL_POINTS
from .refine import DenseFit
from .registration import VOXEL_FRACTION, extent_m, register_consecutive

# Registration works on a thinned copy of each frame: this many points at most.
REGISTRATION_POINTS = 60_000
SURFEL_FRACTION = 1 / 100
# Nor narrower than this many range sigmas: a face seen head-on has its range noise along its
# normal, and a cell narrower than about sqrt(12 / MAX_FLATNESS) = 6.3 of them looks no flatter
# than it is wide (faces.flat_cells). Seen: the long array at 50 m, seed 23, whose frames see it
# end-on (extent 9 m, cells of 9 cm): 52 % of the points in planar cells at the true motion,
# most of a frame's face-on cells out; with cells of 12 cm, 78 %.
SURFEL_MIN_RANGE_SIGMAS = 6.0
# Fewer of the points than this in cells a surface patch can use: the scan is too sparse.
SPARSE_SHARE = 0.5


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
    reg = RegistrationPoints(cloud.xyz_m[thin], cloud.t_s[thin] - T, frames.frame[thin])
    per_frame = reg.split(reg.xyz_m, n_frames)
    extent = extent_m(per_frame)
    noise = opts.sensor or SensorNoise()
    data = prepare(
        cloud.xyz_m,
        cloud.t_s - T,
        frames.frame,
        surfel_m=opts.dense.surfel_m or surfel_size_m(extent, noise.range_sigma_m),
        range_sigma_m=noise.range_sigma_m,
    )
    # 2-3. Register, initialize and refine on all frames, from up to three starts.
    progress("registering", 0.0)
    voxel = max(extent * VOXEL_FRACTION, 1e-3)
    global_pairs = register_consecutive(per_frame, voxel_m=voxel, seed=opts.seed)
    mid = _frame_taus(reg.tau_s, reg.frame, n_frames)
    setup = Setup(data, reg, mid, voxel, extent, opts, noise, progress)
    try:
        best, warnings, attempts = best_attempt(setup, global_pairs, n2)
    except NoSurfacesError as exc:
        sparse = _too_sparse(data)
        if sparse is None:
            raise
        raise NoSurfacesError(
            f"no planar patch of one frame could be matched in another: {sparse}", field=exc.field
        ) from None
    if data.spurious:
        warnings.append(
            f"{data.spurious} points ({100 * data.spurious / len(cloud):.1f} %) were left out of the fit as spurious "
            "returns (ranges far from the rest of their patch); they are rectified with the others"
        )
    main, fit, check = best.solve, best.fit, best.check
    still_poor = poor_fit(fit)
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


def _too_sparse(data: DenseData) -> str | None:
    """Why no surface matched, when the scan's sampling says it (most points in cells too sparse
    for a surface patch: few lines and pixels for the target's size and range), or None."""
    count = np.bincount(data.cell, minlength=len(data.cell_frame))
    share = float(np.mean(count[data.cell] >= MIN_SURFEL_POINTS))
    if share >= SPARSE_SHARE:
        return None
    return (
        f"the scan is too sparse for this target at this range (only {100 * share:.0f} % of the points lie in "
        f"cells {100 * data.surfel_m:.3g} cm across holding the {MIN_SURFEL_POINTS} a patch needs); scan with more "
        "lines and pixels, or from a shorter range"
    )


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


def _result(
    frames: Frames,
    fit: DenseFit,
    main: Solve,
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
                "path": f"{main.path} ({main.pairs_used} of {main.pairs_total} frame pairs agreed"
                + (f"; {fit.members} thin member{'s' * (fit.members > 1)} fitted as lines)" if fit.members else ")"),
                "iterations": fit.iterations,
                "attempts": attempts,
                "elapsed_s": elapsed_s,
            },
            "warnings": warnings,
        }
    )


def surfel_size_m(extent_m: float, range_sigma_m: float) -> float:
    """The surfel (cell) size for a target ``extent_m`` across (metres) seen with range noise
    ``range_sigma_m``: ``extent / 100``, and at least ``SURFEL_MIN_RANGE_SIGMAS`` range sigmas."""
    return max(extent_m * SURFEL_FRACTION, SURFEL_MIN_RANGE_SIGMAS * range_sigma_m)
