"""The starts the frames estimator tries, each carried through to a checked motion.

A start (a motion most registered pairs agree with) is re-timed and registered again, refined
on every point (:mod:`.refine`), given the model choice (Wald test on the precession rate) and
validated on the first frames (a poor fit only if no start is sound: another start replaces it
whatever its check says). :func:`best_attempt` tries the vote on rotation angles, the
consensus over triplets of pairs and the swarm on the dense cost in turn, and keeps the first
sound attempt or the least flawed one.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ..._typing import FloatArray, Progress
from ..errors import FramesUnusableError, NoSurfacesError
from ..initializer import InitialGuess
from ..options import FramesOptions
from ..sensor import SensorNoise
from ..validation import Similarity, similarity
from .consensus import INLIER_RAD, pair_misfit, without_precession
from .data import DenseData
from .degeneracy import precession_p_value
from .refine import DenseFit, refine_dense
from .registration import PairTransforms, register_consecutive
from .search import OverlapCost, swarm_start
from .starts import Start, consensus_start, registration_start, retimed, same_basin, vote

RETIME_PASSES = 2
# A refined motion whose residuals are this many times their model sigma is wrong.
POOR_SCALE = 3.0
# A start whose first or second stage of refinement leaves its residuals this many times their
# model sigma is given up there when another start remains: the later stages do not leave its
# basin (the long array at 100 m seed 1: 17.6 after the first stage, 22.8 after 9 s more; every
# sound refinement of the real-shapes bench's seeds 0-19, 240 jobs, stood at 0.95-1.24 after the
# first stage, and of seeds 0-9 at 0.37-1.03 after the second: bench.linescan.stage_scales);
# within the stage already once refine.GIVE_UP_STEPS of its steps leave them over it.
GIVE_UP_SCALE = 3 * POOR_SCALE
CHECK_FAILED = "the two-frame-count check failed"
# Below this RMS residual (metres) the data count as noise-free: the paper's fixed threshold applies.
NOISE_FREE_RMS_M = 1e-7


@dataclass(frozen=True)
class RegistrationPoints:
    """The thinned cloud registration works on: positions, offsets from ``T``, frames."""

    xyz_m: FloatArray
    tau_s: FloatArray
    frame: NDArray[np.int64]

    def split(self, xyz_m: FloatArray, n: int) -> list[FloatArray]:
        """``xyz_m`` (one row per point here) split into the ``n`` frames."""
        return [xyz_m[self.frame == f] for f in range(n)]


@dataclass(frozen=True)
class Setup:
    """What every attempt at the motion shares: the dense data, the thinned cloud registration
    works on, the frames' mean times, the registration voxel and the caller's options."""

    data: DenseData
    reg: RegistrationPoints
    mid: FloatArray
    voxel_m: float
    extent_m: float
    opts: FramesOptions
    noise: SensorNoise
    progress: Progress


@dataclass(frozen=True)
class Solve:
    fit: DenseFit
    initial: InitialGuess
    pairs_used: int
    pairs_total: int
    path: str
    give_up: bool = False  # another start remains: a refinement may be given up (``GIVE_UP_SCALE``)


@dataclass(frozen=True)
class Attempt:
    """One start carried through: its solve, the fit after the model choice, the check on the
    first frames, and its warnings."""

    solve: Solve
    fit: DenseFit
    check: Similarity | None
    warnings: list[str]
    # The model choice contradicted itself: no significant precession, yet the spin-only model
    # does not fit (a start whose motion cannot pin the precession down, not the motion).
    model_doubt: str | None = None

    def problem(self) -> str | None:
        """Why another start should be tried, or None when this one is sound. A frame without a
        match (an edge-on view) is noted, not a reason: it says nothing against the motion. Most
        frames without one are: the motion maps no frame's surfaces onto the others' (seen on the
        long array at 50 m, seed 8: 13 of 15 unmatched, sigmas of 500-1300 deg, one start tried)."""
        poor = poor_fit(self.fit)
        if poor is not None:
            return poor
        if self.unmatched > len(self.fit.frame_rms_m) // 2:
            return f"{self.unmatched} of {len(self.fit.frame_rms_m)} frames matched no surface in another"
        if self.model_doubt is not None:
            return self.model_doubt
        if self.check is not None and not self.check.passed:
            return CHECK_FAILED
        return None

    def flaws(self) -> tuple[bool, bool, bool, int, float]:
        """Order of preference: a fit that is not poor, a model choice without doubt, a check
        that passed, fewer unmatched frames, smaller residuals."""
        failed = self.check is not None and not self.check.passed
        return (poor_fit(self.fit) is not None, self.model_doubt is not None, failed, self.unmatched, self.fit.scale)

    @property
    def unmatched(self) -> int:
        """Frames with no surface matched in another (an edge-on view, or a wrong motion)."""
        return int(np.sum(~np.isfinite(self.fit.frame_rms_m)))


def best_attempt(setup: Setup, global_pairs: PairTransforms, n2: int) -> tuple[Attempt, list[str], int]:
    """The vote on rotation angles, then, if its motion fits poorly or fails the check, the
    consensus over triplets of pairs, then the swarm on the dense cost: the first sound attempt,
    or the least flawed one, its warnings and how many starts were made."""
    mid, seed = setup.mid, setup.opts.seed
    starts = (
        (lambda: vote(global_pairs, mid), "registration+cone+dense"),
        (lambda: consensus_start(global_pairs, mid, seed), "registration+consensus+dense"),
        (lambda: _swarm(setup, global_pairs), "registration+swarm+dense"),
    )
    best: Attempt | None = None
    made_attempts: list[Attempt] = []
    tried: list[str] = []
    made = 0
    confirmed = False  # a second start led where a motion that failed the check only ended
    unmatched: list[NoSurfacesError] = []  # starts from which no patch matched another frame's
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
        try:
            start = begin()
            if best is not None and isinstance(start, Start) and same_basin(start.guess.x, best.fit.x):
                # Refined, it would end where the last one did (and fail the same way): 10-40 s
                # of registration and refinement for nothing.
                tried.append(f"{path}: starts where the motion above ended, not refined again")
                confirmed = _check_only(best)
                continue
            # The last start is refined to the end: if no start is sound, the least flawed is reported.
            solve = _solve(setup, global_pairs, start, path=path, give_up=made < len(starts))
        except NoSurfacesError as exc:
            # From a wrong start no patch may land on another frame's: the next start may do.
            unmatched.append(exc)
            tried.append(f"{path}: {exc}")
            continue
        except FramesUnusableError as exc:
            tried.append(f"{path}: {exc}")
            continue
        attempt = _judged(setup, solve, n2)
        made_attempts.append(attempt)
        ended_alike = best is not None and same_basin(attempt.fit.x, best.fit.x)
        confirmed = ended_alike and _check_only(attempt)
        if best is None or attempt.flaws() < best.flaws():
            best = attempt
        problem = attempt.problem()
        if problem is None:
            break
        tried.append(f"{path}: {problem}" + (" (it ended where the motion above did)" if ended_alike else ""))
    if best is None and len(unmatched) == len(tried):
        raise unmatched[0]  # from every start: the frames' surfaces, not the starts, are at fault
    if best is None:
        raise FramesUnusableError("the motion could not be estimated: " + "; ".join(tried), field="file")
    if best.problem() is not None and any(a.check is None for a in made_attempts):
        # No start was sound: the checks skipped on poor fits rank those as the others are ranked.
        best = min((_checked(setup, a, n2) for a in made_attempts), key=Attempt.flaws)
    kept = list(best.warnings)
    if tried:
        outcome = "no start was sound" if best.problem() else "the motion comes from " + best.solve.path
        kept.append(f"{len(tried)} start(s) tried before ({'; '.join(tried)}); {outcome}")
    return best, kept, made


def _check_only(attempt: Attempt | None) -> bool:
    """Whether the attempt's motion fits the points and failed the check only."""
    return attempt is not None and attempt.problem() == CHECK_FAILED


def _judged(setup: Setup, solve: Solve, n2: int) -> Attempt:
    """The model choice and the two-frame-count check on one solve."""
    fit, opts = solve.fit, setup.opts
    warnings: list[str] = []
    # 4. Model choice.
    p_value = precession_p_value(fit.x, fit.cov) if opts.model == "auto" else 0.0
    model_doubt = None
    if p_value >= opts.significance:
        setup.progress("refining", 0.66)
        full_poor = poor_fit(fit)
        # From a start in another basin the spin-only refit is as wrong as the full one was (seen:
        # 32-37 times their size at every stage, 7 s): given up as that one would be. Not from a
        # sound fit's start: without its precession that start may well be off after one stage.
        spin = refine_dense(
            setup.data,
            solve.initial.x_spin_only,
            spin_only=True,
            config=opts.dense,
            noise=setup.noise,
            seed=opts.seed,
            give_up_scale=GIVE_UP_SCALE if solve.give_up and full_poor is not None else None,
        )
        spin_poor = poor_fit(spin)
        if spin_poor is None or (full_poor is not None and spin.residuals > 0):
            fit = spin
            warnings.append(
                f"no significant precession (Wald test p={p_value:.3g}): reporting the spin-only model; the "
                "precession axis and the centre's position along the spin axis are unobservable"
            )
        else:
            # The spin-only refit lost what the full one fits (seen: every frame unmatched, which
            # reported 0 +- 0 deg/s with a passed check): keep the model that fits the points, and
            # let another start try to pin the precession down.
            doubt = (
                f"no significant precession (Wald test p={p_value:.3g}), but the spin-only refit does not fit "
                f"the frames ({spin_poor})"
            )
            warnings.append(doubt + ": reporting the spin-precession model")
            model_doubt = doubt
    attempt = Attempt(solve, fit, None, warnings, model_doubt)
    # 5. Validate: do the first n2 frames alone support the motion? Not yet for a poor fit, which
    # another start replaces whatever the check says (2-3 s a start; best_attempt checks it later
    # only if no start is sound).
    return attempt if poor_fit(fit) is not None else _checked(setup, attempt, n2)


def _checked(setup: Setup, attempt: Attempt, n2: int) -> Attempt:
    """The attempt with its check on the first ``n2`` frames (none when they are all the frames)."""
    if attempt.check is not None or n2 >= setup.data.n_frames:
        return attempt
    setup.progress("validating", 0.7)
    return replace(attempt, check=_validate(setup, n2, attempt.fit))


def _solve(setup: Setup, pairs: PairTransforms, start: Start, *, path: str, give_up: bool) -> Solve:
    """From a motion most pairs agree with: re-time and register again, refine on every point
    (given up in the first or second stage of refinement, if ``give_up``, when that stage leaves
    the residuals over ``GIVE_UP_SCALE`` times their size, or 8 of its steps do: ``refine.GIVE_UP_STEPS``)."""
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
    # Pairs that disagree with the rest (a symmetric target registered onto a turned copy of itself)
    # are routine and left out of the start; the result's solver path counts them, not a warning.
    used = int(start.inliers.sum())
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
        give_up_scale=GIVE_UP_SCALE if give_up else None,
    )
    if fit.residuals == 0:
        raise NoSurfacesError(
            "no planar patch of one frame could be matched in another (are the frames of one rigid target, and "
            "is the declared range noise right?)",
            field="file",
        )
    return Solve(fit, guess, used, len(start.inliers), path, give_up)


def poor_fit(fit: DenseFit) -> str | None:
    """Why the refined motion cannot be right, or None: residuals many times their model sigma,
    or none at all (no surface of one frame lands on another's: nothing supports the motion)."""
    if fit.residuals == 0:
        return "no surface of one frame matched in another"
    if fit.given_up:
        # Poor whatever its own scale: a half-refined motion (the scale the fit reports, of the
        # surfel pairs alone, may fall under POOR_SCALE where every row's stood over the give-up).
        stage = ("first", "second")[fit.given_up - 1]  # never the last of the three
        return (
            f"residuals {fit.given_up_scale:.1f} times their expected size in the {stage} stage of refinement "
            "(given up there)"
        )
    if not fit.scale <= POOR_SCALE:
        return f"residuals {fit.scale:.1f} times their expected size"
    return None


def _swarm(setup: Setup, pairs: PairTransforms) -> Start:
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


def _validate(setup: Setup, n2: int, fit: DenseFit) -> Similarity:
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
