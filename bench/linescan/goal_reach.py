"""Could any estimator meet issue 20's accuracy goal? The bound's answer, on many motions.

    python -m bench.linescan.goal_reach [--motions 50] [--distances 50 100] [--shapes ...]
                                        [--bench bench/out/real_shapes.json]
    python -m bench.linescan.goal_reach --report bench/out/goal_reach.json [...]

The goal: on every shape, >= 95 % of the real-shapes bench's cases (10 seeded motions at each
of 50 and 100 m) within 0.05 deg/s and 0.1 deg. For each motion of the sweep (the bench's seeds
and more, the same seeded motions and frames), the dense Cramer-Rao bound (``dense_bound.py``)
gives ``p``, the probability that an unbiased estimate at the bound lies within those limits:
one modelling the target as planes (the mesh's faces as nuisance planes), and one given the
exact shape (only its pose unknown; no estimator using these hits does better). Per shape:

- ``share``: the mean of ``p`` over the swept motions, what such an estimator scores on the
  paper's grid of motions, with its standard error over the motions;
- ``P(goal)``: the probability that it scores >= 95 % on a bench of ``BENCH_MOTIONS`` motions
  per range drawn from that grid (Monte Carlo: motions resampled from the sweep, each case within
  the limits with its ``p``), and on the bench's own motions (seeds ``0 .. BENCH_MOTIONS - 1``,
  exactly: the Poisson-binomial distribution of the count);
- the same for all shapes at once (independent shapes: the product);
- ``k x bound``: the share, and ``P(goal)`` on exactly the swept motions, of an unbiased
  estimator whose covariance is ``k^2`` times the planes' bound (``k`` in ``INFLATIONS``): how
  close to efficient an estimator must be to meet the goal (ours reports 1.5-2 bounds).

``--bench`` adds the estimator's own share on the saved real-shapes run beside them. Writes
``bench/out/goal_reach.json`` after every shape and range (a long sweep can be reported while it
runs) and a plot of each shape's ``p`` over the motions.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from tumblescan import Scanner, Scene, random_motion, simulate_frames
from tumblescan.linescan.dense.degeneracy import AXIS_LIMIT_DEG, RATE_LIMIT_DEG_S
from tumblescan.target.shapes import PARAMETRIC

from ..common import out_dir, table
from .dense_bound import bound_covariances, share_within
from .real_shapes import shape_named, start_run

GOAL_SHARE = 0.95
BENCH_MOTIONS = 10  # per range, as the real-shapes bench runs
RESAMPLES = 20_000
MODELS = ("planes", "known_shape")
# Estimators k times the planes' bound in every direction (covariance k^2 times it).
INFLATIONS = (1.1, 1.2, 1.5, 2.0)


@dataclass
class Reach:
    """One motion: the probability an efficient estimator lands within the limits, per model."""

    shape: str
    distance_m: float
    seed: int
    planes: float
    known_shape: float
    # str(k) -> the probability for an estimator at k times the planes' bound (INFLATIONS).
    inflated: dict[str, float] = field(default_factory=dict)


def reach(name: str, distance_m: float, seed: int, size: int) -> Reach:
    """The bench's seeded motion and frames (``real_shapes.one``), at the estimate's reference
    time (the first hit's), against the fixed limits."""
    motion = random_motion(np.random.default_rng(seed), distance_m=distance_m)
    scene = Scene(scanner=Scanner(lines=size, pixels=size), shape=shape_named(name))
    sim = simulate_frames(motion, scene, seed=seed)
    b = bound_covariances(motion, scene, sim, float(sim.t_s.min()))
    p = {
        model: share_within(b.x, cov, AXIS_LIMIT_DEG, RATE_LIMIT_DEG_S)
        for model, cov in zip(MODELS, (b.facets, b.known_shape), strict=True)
    }
    inflated = {str(k): share_within(b.x, k**2 * b.facets, AXIS_LIMIT_DEG, RATE_LIMIT_DEG_S) for k in INFLATIONS}
    return Reach(name, distance_m, seed, **p, inflated=inflated)


def count_distribution(p: np.ndarray) -> np.ndarray:
    """Poisson-binomial: ``out[k]`` is the probability that exactly ``k`` of independent cases,
    case ``i`` a success with probability ``p[i]``, succeed."""
    out = np.zeros(len(p) + 1)
    out[0] = 1.0
    for i, pi in enumerate(p):
        out[1 : i + 2] = out[1 : i + 2] * (1 - pi) + out[: i + 1] * pi
        out[0] *= 1 - pi
    return out


def goal_met_exactly(p: np.ndarray, share: float = GOAL_SHARE) -> float:
    """Probability that at least ``share`` of the cases with success probabilities ``p`` succeed."""
    need = int(np.ceil(share * len(p) - 1e-9))
    return float(count_distribution(p)[need:].sum())


def goal_met_resampled(
    p_by_range: list[np.ndarray], per_range: int, rng: np.random.Generator, share: float = GOAL_SHARE
) -> float:
    """Probability that a bench of ``per_range`` motions per range, drawn (with replacement) from
    each range's swept motions ``p_by_range``, has at least ``share`` of its cases succeed."""
    need = int(np.ceil(share * per_range * len(p_by_range) - 1e-9))
    hits = np.zeros(RESAMPLES, dtype=np.int64)
    for p in p_by_range:
        drawn = p[rng.integers(0, len(p), size=(RESAMPLES, per_range))]
        hits += np.sum(rng.random(drawn.shape) < drawn, axis=1)
    return float(np.mean(hits >= need))


def summary(
    reaches: list[Reach], bench: dict[str, float] | None
) -> tuple[list[list[object]], dict[str, dict[str, float]]]:
    """Rows per shape, and the probability that every shape meets the goal at once per model
    (``resampled`` and ``bench seeds``)."""
    rng = np.random.default_rng(0)
    rows: list[list[object]] = []
    everything = {m: {"resampled": 1.0, "bench seeds": 1.0} for m in MODELS}
    for name in dict.fromkeys(r.shape for r in reaches):
        mine = [r for r in reaches if r.shape == name]
        ranges = sorted({r.distance_m for r in mine})
        row: list[object] = [name, "/".join(str(sum(r.distance_m == d for r in mine)) for d in ranges)]
        for model in MODELS:
            p = np.array([getattr(r, model) for r in mine])
            by_range = [np.array([getattr(r, model) for r in mine if r.distance_m == d]) for d in ranges]
            seeds = np.array([getattr(r, model) for r in mine if r.seed < BENCH_MOTIONS])
            resampled = goal_met_resampled(by_range, BENCH_MOTIONS, rng)
            exact = goal_met_exactly(seeds)
            everything[model]["resampled"] *= resampled
            everything[model]["bench seeds"] *= exact
            se = p.std(ddof=1) / np.sqrt(len(p)) if len(p) > 1 else float("nan")
            row += [f"{100 * p.mean():.1f} +- {100 * se:.1f} %", f"{resampled:.2f}", f"{exact:.2f}"]
        row.append("-" if bench is None or name not in bench else f"{100 * bench[name]:.0f} %")
        rows.append(row)
    return rows, everything


def inflation_rows(reaches: list[Reach], bench: dict[str, float] | None) -> tuple[list[list[object]], list[float]]:
    """Per shape: the share within the limits, and ``P(goal)`` on exactly the swept motions, of
    an estimator at the planes' bound and at ``k`` times it (``INFLATIONS``); and per factor the
    probability that every shape meets the goal at once."""
    rows: list[list[object]] = []
    at_once = np.ones(1 + len(INFLATIONS))
    for name in dict.fromkeys(r.shape for r in reaches):
        mine = [r for r in reaches if r.shape == name and r.inflated]
        if not mine:
            continue
        columns = [np.array([r.planes for r in mine])]
        columns += [np.array([r.inflated[str(k)] for r in mine]) for k in INFLATIONS]
        odds = np.array([goal_met_exactly(p) for p in columns])
        at_once *= odds
        row: list[object] = [name, len(mine)]
        row += [f"{100 * p.mean():.1f} % ({o:.2f})" for p, o in zip(columns, odds, strict=True)]
        row.append("-" if bench is None or name not in bench else f"{100 * bench[name]:.1f} %")
        rows.append(row)
    return rows, [float(o) for o in at_once]


def bench_shares(path: Path) -> dict[str, float]:
    """The estimator's share within the limits per shape, from a saved real-shapes run."""
    cases = json.loads(path.read_text())
    return {
        name: float(np.mean([c["within_limits"] for c in cases if c["shape"] == name]))
        for name in dict.fromkeys(c["shape"] for c in cases)
    }


def plot(reaches: list[Reach], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(dict.fromkeys(r.shape for r in reaches))
    fig, ax = plt.subplots(figsize=(9, 4.5))
    for i, name in enumerate(names):
        for distance, marker, color, side in ((50.0, "o", "tab:blue", -0.2), (100.0, "s", "tab:orange", 0.2)):
            p = np.array([r.planes for r in reaches if r.shape == name and r.distance_m == distance])
            if len(p):
                jitter = np.random.default_rng(i).uniform(-0.15, 0.15, len(p))
                ax.scatter(i + side + jitter, 1 - p, s=12, marker=marker, color=color,
                           label=f"{distance:g} m" if i == 0 else None)  # fmt: skip
    ax.axhline(1 - GOAL_SHARE, color="grey", ls="--", lw=1)
    ax.set_yscale("symlog", linthresh=1e-3)
    ax.set_ylim(0, 1)
    ax.set_xticks(range(len(names)), names)
    ax.set_ylabel("probability an efficient estimate misses the limits")
    ax.set_title("Per motion, at the dense bound (planes); dashed: the goal's 5 %")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def report(reaches: list[Reach], bench: dict[str, float] | None) -> None:
    rows, everything = summary(reaches, bench)
    header = ["shape", "motions (50/100 m)"]
    for model in ("planes", "known shape"):
        header += [f"{model}: share", f"{model}: P(goal), resampled", f"{model}: P(goal), bench seeds"]
    header.append("ours on the bench")
    print(table(rows, header))
    for model in MODELS:
        both = everything[model]
        print(
            f"every shape at once, {model.replace('_', ' ')}: P(goal) {both['resampled']:.2f} on resampled "
            f"benches, {both['bench seeds']:.2f} on the bench's own motions"
        )
    rows, at_once = inflation_rows(reaches, bench)
    if rows:
        print("\nAn unbiased estimator at k times the planes' bound, on exactly the swept motions: share (P(goal))")
        header = ["shape", "cases", "k = 1", *(f"k = {k:g}" for k in INFLATIONS), "ours on the bench"]
        print(table(rows, header))
        odds = ", ".join(f"k = {k:g}: {o:.2f}" for k, o in zip((1, *INFLATIONS), at_once, strict=True))
        print(f"every shape at once on these motions: P(goal) {odds}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--motions", type=int, default=50, help="per shape and range (seeds 0 .. motions - 1)")
    parser.add_argument("--distances", type=float, nargs="+", default=[50.0, 100.0])
    parser.add_argument("--size", type=int, default=512, help="lines and pixels per frame")
    parser.add_argument("--shapes", nargs="+", default=["box", *PARAMETRIC, "hubble"])
    parser.add_argument("--stem", default="goal_reach", help="name of the JSON and plot in bench/out")
    parser.add_argument("--report", nargs="+", type=Path, help="only report saved sweeps' JSON")
    parser.add_argument("--bench", type=Path, help="a saved real-shapes run, for the estimator's own share")
    args = parser.parse_args()
    bench = bench_shares(args.bench) if args.bench else None
    if args.report:
        report([Reach(**r) for path in args.report for r in json.loads(path.read_text())], bench)
        return
    args.shapes = start_run(args.shapes)
    out = out_dir()
    reaches: list[Reach] = []
    for name in args.shapes:
        for distance in args.distances:
            reaches += [reach(name, distance, seed, args.size) for seed in range(args.motions)]
            (out / f"{args.stem}.json").write_text(json.dumps([asdict(r) for r in reaches], indent=1))
            print(f"  {name} at {distance:g} m done", flush=True)
    report(reaches, bench)
    plot(reaches, out / f"{args.stem}.png")
    print(f"wrote {out / args.stem}.json and .png")


if __name__ == "__main__":
    main()
