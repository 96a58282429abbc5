"""The residuals' scale after each stage of refinement: sound refinements against wrong starts.

    python -m bench.linescan.stage_scales [--motions 10] [--first-seed 0] [--distances 50 100]
                                          [--shapes box telescope ...] [--stem NAME]
    python -m bench.linescan.stage_scales --wrong-starts 2 3 4 5 6 7 8 [--cases long-array:100:1]
    python -m bench.linescan.stage_scales --cases hubble:50:6 box:50:7

What ``attempts.GIVE_UP_SCALE`` rests on. Every refinement of a whole dense estimate is recorded:
after each of its stages the common scale that stage weighed its rows by (``s = 1.4826
median |r / sqrt(var)|`` over every row of its last linearisation: the surfel pairs', from the
second stage the thin members' and in the last the grazing groups' too; about 1 when the motion
is right, dimensionless), the fit's own ``DenseFit.scale`` where it ended (the same statistic
of the pairs alone, at the final motion), in which stage it was given up, if it was, and the
scale after each step of each stage (``refine.GIVE_UP_STEPS``: a stage may be given up within).

The first form runs the real-shapes bench's seeded motions (the default starts, as a user gets
them); the second replaces the vote's turns with those of other seeds' motions (a start in
another basin, as ``tests/linescan/dense/test_refine`` does for one; the re-timed votes within
the solve too) on each case given; the third, only the cases given. ``--no-give-up`` sets
``GIVE_UP_SCALE`` to infinity for the run, so that every refinement runs to the end and what a
give-up would drop is seen. It prints, per stage, the scales of the refinements that ended sound
(at most ``POOR_SCALE``) and of those that ended poor or were given up, and how many of each
stood over ``GIVE_UP_SCALE`` after that stage; each job's time; writes ``bench/out/STEM.json``.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from tumblescan import estimate_from_frames, random_motion
from tumblescan.linescan.dense import attempts, refine
from tumblescan.linescan.dense.registration import PairTransforms
from tumblescan.linescan.dense.starts import Start

from ..common import ShapeCase, add_cases, out_dir, table
from .dense import errors
from .real_shapes import frames_of, simulated, start_run, within_limits

STAGES = 3


@dataclass
class Refinement:
    """One call of ``refine_dense`` within a job: the scale after each stage it ran, where it ended."""

    stages: list[float]
    final: float
    given_up: int  # the stage in which it was given up; 0: every stage ran
    spin_only: bool
    full: bool  # every stage from a start (not the validation's or a refit's last stage alone)
    steps: list[list[float]] = field(default_factory=list)  # per stage, the scale after 0, 1, ... steps


@dataclass
class Job:
    case: str
    wrong_seed: int | None  # the seed whose turns replaced the vote's, or None (the default starts)
    seconds: float
    within_limits: bool
    refinements: list[Refinement] = field(default_factory=list)


@contextmanager
def recording() -> Iterator[list[Refinement]]:
    """Record every refinement the estimate makes (``attempts`` and ``degeneracy`` call it by
    the name they imported, so the wrapper replaces those names too)."""
    from tumblescan.linescan.dense import degeneracy

    made: list[Refinement] = []
    scales: list[float] = []
    steps: list[list[float]] = []  # the current refinement's, per stage
    stepping = [False]  # within a stage: the weights of the fit's _finish are not a step's
    iterate, weights, refine_dense = refine._iterate, refine.weights, refine.refine_dense

    def counted(*args: Any, **kwargs: Any) -> Any:
        steps.append([])
        stepping[0] = True
        try:
            out = iterate(*args, **kwargs)
        finally:
            stepping[0] = False
        scales.append(float(out[-1]))
        return out

    def weighed(*args: Any, **kwargs: Any) -> Any:
        out = weights(*args, **kwargs)
        if stepping[0]:
            steps[-1].append(float(out[1]))
        return out

    def recorded(*args: Any, **kwargs: Any) -> Any:
        scales.clear()
        steps.clear()
        fit = refine_dense(*args, **kwargs)
        full = not kwargs.get("converged", False)
        made.append(
            Refinement(list(scales), float(fit.scale), int(fit.given_up), bool(fit.spin_only), full, list(steps))
        )
        return fit

    saved = [(refine, "_iterate", iterate), (refine, "weights", weights)]
    saved += [(attempts, "refine_dense", attempts.refine_dense), (degeneracy, "refine_dense", degeneracy.refine_dense)]
    refine._iterate = counted
    refine.weights = weighed
    attempts.refine_dense = recorded
    degeneracy.refine_dense = recorded
    try:
        yield made
    finally:
        for module, name, value in saved:
            setattr(module, name, value)


@contextmanager
def vote_replaced(turns_seed: int | None, distance_m: float) -> Iterator[None]:
    """The vote's start with the turns (the first six parameters) of seed ``turns_seed``'s motion:
    a start in another basin; nothing replaced when ``turns_seed`` is None."""
    found = attempts.vote
    if turns_seed is None:
        yield
        return

    def astray(pairs: PairTransforms, mid: np.ndarray) -> Start:
        start = found(pairs, mid)
        x = start.guess.x.copy()
        x[:6] = random_motion(np.random.default_rng(turns_seed), distance_m=distance_m).params()[:6]
        return replace(start, guess=replace(start.guess, x=x))

    attempts.vote = astray
    try:
        yield
    finally:
        attempts.vote = found


def job(case: ShapeCase, wrong_seed: int | None, size: int) -> Job:
    """The whole dense estimate on the case's seeded frames, every refinement recorded."""
    motion, _, sim = simulated(case.name, case.distance_m, case.seed, size)
    frames = frames_of(sim)
    with recording() as made, vote_replaced(wrong_seed, case.distance_m):
        started = time.perf_counter()
        result = estimate_from_frames(frames)
        seconds = time.perf_counter() - started
    return Job(str(case), wrong_seed, seconds, within_limits(errors(result, motion)), made)


def sound_and_poor(jobs: list[Job]) -> tuple[list[Refinement], list[Refinement]]:
    """The jobs' refinements from a start: those that ended sound (at most ``POOR_SCALE``, not
    given up), and the others."""
    full = [r for j in jobs for r in j.refinements if r.full]
    sound = [r for r in full if not r.given_up and r.final <= attempts.POOR_SCALE]
    return sound, [r for r in full if r not in sound]


def stage_rows(jobs: list[Job]) -> list[list[object]]:
    """Per stage: the scales of the full refinements that ended sound and of the others, and how
    many sound ones a give-up at ``GIVE_UP_SCALE`` after that stage would have dropped."""
    sound, poor = sound_and_poor(jobs)
    rows: list[list[object]] = []
    for k in range(STAGES - 1):
        ok = [r.stages[k] for r in sound if len(r.stages) > k]
        bad = [r.stages[k] for r in poor if len(r.stages) > k]
        rows.append([
            k + 1,
            len(ok),
            spread(ok),
            len(bad),
            " ".join(f"{s:.1f}" for s in sorted(bad)) or "-",
            sum(s > attempts.GIVE_UP_SCALE for s in ok),
            sum(s > attempts.GIVE_UP_SCALE for s in bad),
        ])  # fmt: skip
    return rows


def step_rows(jobs: list[Job], after: tuple[int, ...] = (2, 4, 6, 8, 10, 14)) -> list[list[object]]:
    """The first stage, after ``k`` of its steps: the largest scale of the full refinements that
    ended sound and the smallest of the others, among those still stepping then, and how many of
    each stood over ``GIVE_UP_SCALE`` (what ``refine.GIVE_UP_STEPS`` rests on)."""
    sound, poor = sound_and_poor(jobs)
    rows: list[list[object]] = []
    for k in after:
        ok = [r.steps[0][k] for r in sound if r.steps and len(r.steps[0]) > k]
        bad = [r.steps[0][k] for r in poor if r.steps and len(r.steps[0]) > k]
        rows.append([
            k,
            len(ok),
            f"{max(ok):.2f}" if ok else "-",
            sum(s > attempts.GIVE_UP_SCALE for s in ok),
            len(bad),
            f"{min(bad):.2f}" if bad else "-",
            sum(s > attempts.GIVE_UP_SCALE for s in bad),
        ])  # fmt: skip
    return rows


def spread(values: list[float]) -> str:
    """``min / median / max`` of ``values``, or ``-``."""
    if not values:
        return "-"
    return f"{np.min(values):.2f} / {np.median(values):.2f} / {np.max(values):.2f}"


def job_rows(jobs: list[Job]) -> list[list[object]]:
    """One row per job: its case, the wrong turns' seed, its time, whether within the limits, and
    each refinement from a start as its stages' scales and where it ended."""
    rows: list[list[object]] = []
    for j in jobs:
        full = [r for r in j.refinements if r.full]
        path = "; ".join(
            " > ".join(f"{s:.2f}" for s in r.stages) + (" (given up)" if r.given_up else f" = {r.final:.2f}")
            for r in full
        )
        rows.append([j.case, "-" if j.wrong_seed is None else j.wrong_seed, f"{j.seconds:.1f}", j.within_limits, path])
    return rows


def report(jobs: list[Job], stem: str) -> None:
    """Print the per-stage table and the jobs' table; write ``bench/out/STEM.json``."""
    print(
        f"\nScale after each stage of the refinements from a start (min / median / max; give-up at "
        f"{attempts.GIVE_UP_SCALE:g}, poor above {attempts.POOR_SCALE:g} at the end):"
    )
    print(table(stage_rows(jobs), ["after stage", "ended sound", "their scale", "ended poor or given up",
                                   "their scales", "sound over give-up", "poor over give-up"]))  # fmt: skip
    print(f"\nThe first stage's scale after k of its steps (give-up within a stage after {refine.GIVE_UP_STEPS}):")
    print(table(step_rows(jobs), ["k", "ended sound, still stepping", "largest", "over give-up",
                                  "poor or given up, still stepping", "smallest", "over give-up"]))  # fmt: skip
    print("\nEach job: its refinements from a start, scale after each stage (= where it ended):")
    print(table(job_rows(jobs), ["case", "wrong turns' seed", "s", "within limits", "refinements"]))
    path = out_dir() / f"{stem}.json"
    path.write_text(json.dumps([asdict(j) for j in jobs], indent=1))
    print(f"wrote {path}")


def main() -> None:
    """Run the jobs the command line names and report them."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--motions", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--distances", type=float, nargs="+", default=[50.0, 100.0])
    parser.add_argument("--shapes", nargs="+", default=["dish-boom", "long-array", "octagon-truss"])
    parser.add_argument("--size", type=int, default=512, help="lines and pixels per frame")
    parser.add_argument("--wrong-starts", type=int, nargs="+", help="seeds whose turns replace the vote's")
    add_cases(parser)  # only these cases (with --wrong-starts: default long-array:100:1)
    parser.add_argument("--stem", default="stage_scales")
    parser.add_argument("--no-give-up", action="store_true", help="every refinement runs to the end")
    args = parser.parse_args()
    if args.no_give_up:
        attempts.GIVE_UP_SCALE = float("inf")
    shapes = start_run(args.shapes)
    runs: list[tuple[ShapeCase, int | None]]
    if args.wrong_starts:
        runs = [(case, s) for case in args.cases or [ShapeCase("long-array", 100.0, 1)] for s in args.wrong_starts]
    elif args.cases:
        runs = [(case, None) for case in args.cases]
    else:
        seeds = range(args.first_seed, args.first_seed + args.motions)
        runs = [(ShapeCase(n, d, s), None) for n in shapes for d in args.distances for s in seeds]
    jobs: list[Job] = []
    for case, wrong in runs:
        jobs.append(job(case, wrong, args.size))
        print(table(job_rows(jobs[-1:]), ["case", "wrong turns' seed", "s", "within limits", "refinements"]))
    report(jobs, args.stem)


if __name__ == "__main__":
    main()
