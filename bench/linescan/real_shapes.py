"""Dense frames of real spacecraft shapes: the box beside the shape library and a real mesh.

    python -m bench.linescan.real_shapes [--motions 10] [--distances 50 100] [--size 512]
                                          [--shapes box telescope ... hubble] [--stem NAME]
                                          [--first-seed 0] [--no-beams] [--no-grazing]
    python -m bench.linescan.real_shapes --report bench/out/A.json bench/out/B.json [--rebound]

Each case: a seeded motion on the paper's grid, 15 frames (Table 1 scanner and noise) of the
shape at the given range, the whole dense estimate. Per shape and range it prints the share
of cases within the issue's limits (rate 0.05 deg/s and axes 0.1 deg), misses flagged (the
check failed, a warning called the estimate unreliable, or imprecise: a reported sigma over a
third of a limit) and unflagged, cases within the limits but flagged, the share with
every error within 3 reported sigma and any over 5, the share of points the fit used, time
and peak memory; beside them the dense Cramer-Rao bound (``dense_bound.py``, the shape's mesh
faces as nuisance planes): how many motions have a bound whose three times exceeds a limit,
so that no estimator modelling the target as planes meets it reliably, the median reported
sigma over the bound (1 for an efficient estimate), and the share of cases
with every parameter within ``max(floor, 3 x bound)`` (floor 0.01 deg/s and 0.02 deg, the
box's goal), and the share within the fixed limits that an efficient estimator would expect on
these motions: one modelling the target as planes, and one given the exact shape (only its pose
unknown: no estimator using the hits on the surfaces does better). A second table states the
issue's goals per shape, beside the RMS of the errors over the reported sigmas (about 1 when
they are honest) and over the bound (what the estimator achieves). Then each case outside
``max(floor, 3 x bound)``: the misses that are the estimator's, not the data's. Writes
``bench/out/real_shapes.json`` and a plot of error over sigma (``--stem`` renames them, for
runs split by shapes across processes; ``--report`` merges their JSON, and with ``--rebound``
computes the saved cases' bound anew on the same seeded frames).
The Hubble mesh is read from ``../shared/meshes`` and skipped, saying why, when absent.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from tumblescan import (
    FramesOptions,
    Motion,
    Scanner,
    Scene,
    TimedCloud,
    estimate_from_frames,
    random_motion,
    simulate_frames,
)
from tumblescan._open3d import load_open3d
from tumblescan.linescan.dense.degeneracy import AXIS_LIMIT_DEG, RATE_LIMIT_DEG_S
from tumblescan.linescan.frames import Frames, assemble_frames
from tumblescan.linescan.options import DenseConfig
from tumblescan.linescan.simulate import FrameCloud
from tumblescan.target.shape import SatelliteShape
from tumblescan.target.shapes import PARAMETRIC, MeshFileShape

from ..common import machine, out_dir, table
from .dense import errors
from .dense_bound import bound_covariances, bound_sigmas, share_within

HUBBLE = Path(__file__).resolve().parents[3] / "shared" / "meshes" / "hubble_illidroid.glb"
PARAMS = ("spin_axis", "spin_rate", "precession_axis", "precession_rate")
UNITS = {"spin_axis": "deg", "spin_rate": "deg_s", "precession_axis": "deg", "precession_rate": "deg_s"}
# Below these no limit is asked for, whatever the bound (the box's goal in bench.linescan.dense).
FLOOR = {"deg": 0.02, "deg_s": 0.01}


@dataclass
class Case:
    shape: str
    distance_m: float
    seed: int
    errors: dict[str, float]
    within_limits: bool
    flagged: bool
    flag: str  # why: the check failed, a warning called it unreliable, or imprecise; "" if not flagged
    flags: list[str]  # every one of those that holds
    worst_sigma: float
    points_share: float
    seconds: float
    warnings: list[str]
    # The dense Cramer-Rao bound (bench/linescan/dense_bound.py); whether three times it exceeds
    # a limit (no estimator could meet that limit reliably); whether every parameter is within
    # max(floor, 3 x bound), and the thresholds that were asked per parameter.
    bound: dict[str, float]
    below_bound: bool
    within_bound: bool
    bound_limits: dict[str, float]
    reference_time_s: float | None = None  # the estimate's, where the bound is taken


def shape_named(name: str) -> Any:
    if name == "box":
        return SatelliteShape()
    if name == "hubble":
        return MeshFileShape(path=str(HUBBLE), size_m=13.2)
    return PARAMETRIC[name]()


def simulated(name: str, distance_m: float, seed: int, size: int) -> tuple[Motion, Scene, FrameCloud]:
    """The bench's case: seed ``seed``'s motion on the paper's grid at ``distance_m``, the shape
    ``name`` under a ``size`` x ``size`` scanner, and its seeded frames."""
    motion = random_motion(np.random.default_rng(seed), distance_m=distance_m)
    scene = Scene(scanner=Scanner(lines=size, pixels=size), shape=shape_named(name))
    return motion, scene, simulate_frames(motion, scene, seed=seed)


def frames_of(sim: FrameCloud) -> Frames:
    """The simulated frames as a user uploads them: points with their times, frames and lines."""
    return assemble_frames(TimedCloud(sim.xyz_m, sim.t_s, {"frame": sim.frame, "line": sim.line}))


def one(name: str, distance_m: float, seed: int, size: int, options: FramesOptions | None = None) -> Case:
    return estimated(name, distance_m, seed, *simulated(name, distance_m, seed, size), options)


def estimated(
    name: str,
    distance_m: float,
    seed: int,
    motion: Motion,
    scene: Scene,
    sim: FrameCloud,
    options: FramesOptions | None = None,
) -> Case:
    """The whole estimate on the frames ``sim`` of ``motion`` (default options, or ``options``),
    judged against the truth and the bound."""
    frames = frames_of(sim)
    started = time.perf_counter()
    result = estimate_from_frames(frames, options)
    seconds = time.perf_counter() - started
    e = errors(result, motion)
    within = within_limits(e)
    flags = [
        kind
        for kind, hit in (
            ("check", not result.validation.passed),
            ("unreliable", any("unreliable" in w for w in result.warnings)),
            ("imprecise", any(w.startswith("imprecise") for w in result.warnings)),
        )
        if hit
    ]
    flag = flags[0] if flags else ""
    sigmas = [e[f"{p}_sigma"] for p in PARAMS if np.isfinite(e[f"{p}_sigma"])]
    return Case(
        shape=name,
        distance_m=distance_m,
        seed=seed,
        errors={k: float(v) for k, v in e.items()},
        within_limits=bool(within),
        flagged=bool(flag),
        flag=flag,
        flags=flags,
        worst_sigma=float(max(sigmas)),
        points_share=(result.fit.points_used or 0) / result.fit.observations,
        seconds=seconds,
        warnings=result.warnings,
        reference_time_s=result.reference_time_s,
        **against_bound(motion, scene, sim, result.reference_time_s, e),
    )


def within_limits(e: dict[str, float]) -> bool:
    """Whether the errors ``e`` (``bench.linescan.dense.errors``) are within the issue's limits
    (an absent precession axis, a spin-only answer, is not held against the case)."""
    return bool(
        e["spin_rate_deg_s"] <= RATE_LIMIT_DEG_S
        and e["precession_rate_deg_s"] <= RATE_LIMIT_DEG_S
        and e["spin_axis_deg"] <= AXIS_LIMIT_DEG
        and (np.isnan(e["precession_axis_deg"]) or e["precession_axis_deg"] <= AXIS_LIMIT_DEG)
    )


def against_bound(motion: Motion, scene: Scene, sim: FrameCloud, reference_time_s: float, e: dict[str, float]) -> Any:
    """The case's fields of the bound: the bound, whether 3x it exceeds a limit, the thresholds
    max(floor, 3 x bound) per parameter and whether every error ``e`` is within them."""
    b = bound_covariances(motion, scene, sim, reference_time_s)
    bound = bound_sigmas(b.x, b.facets)
    # What an efficient estimator would score against the fixed limits: modelling the target as
    # planes, and given the exact shape (then only its pose at T unknown).
    for key, cov in (("efficient_within_limits", b.facets), ("known_shape_within_limits", b.known_shape)):
        bound[key] = share_within(b.x, cov, AXIS_LIMIT_DEG, RATE_LIMIT_DEG_S)
    below = bool(
        3 * max(bound["spin_axis_deg"], bound["precession_axis_deg"]) > AXIS_LIMIT_DEG
        or 3 * max(bound["spin_rate_deg_s"], bound["precession_rate_deg_s"]) > RATE_LIMIT_DEG_S
    )
    bound_limits = {p: max(FLOOR[UNITS[p]], 3 * bound[f"{p}_{UNITS[p]}"]) for p in PARAMS}
    # An absent precession axis (a spin-only answer) is not held against the case, as above.
    within_bound = all(not e[f"{p}_{UNITS[p]}"] > bound_limits[p] for p in PARAMS)
    return {"bound": bound, "below_bound": below, "within_bound": bool(within_bound), "bound_limits": bound_limits}


def rebound(case: Case, size: int) -> Case:
    """The saved case with its bound computed anew (same seeded frames; the estimate kept)."""
    motion, scene, sim = simulated(case.shape, case.distance_m, case.seed, size)
    # Runs saved before the field: the estimate's reference time is the first point's.
    T = case.reference_time_s if case.reference_time_s is not None else float(sim.t_s.min())
    return replace(case, reference_time_s=T, **against_bound(motion, scene, sim, T, case.errors))


def summary(cases: list[Case]) -> list[object]:
    n = len(cases)
    misses = [c for c in cases if not c.within_limits]
    share = np.array([c.points_share for c in cases])
    return [
        cases[0].shape,
        f"{cases[0].distance_m:g}",
        n,
        f"{100 * (n - len(misses)) / n:.0f} %",
        "/".join(str(sum(c.flag == k for c in misses)) for k in ("check", "unreliable", "imprecise")),
        sum(not c.flagged for c in misses),
        f"{100 * np.mean([c.worst_sigma <= 3 for c in cases]):.0f} %",
        sum(c.flagged and c.within_limits for c in cases),
        sum(c.worst_sigma > 5 and not c.flagged for c in cases),
        f"{100 * share.min():.0f}-{100 * share.max():.0f} %",
        f"{np.median([c.seconds for c in cases]):.1f} / {max(c.seconds for c in cases):.1f}",
        sum(c.below_bound for c in cases),
        f"{np.nanmedian([sigma_over_bound(c) for c in cases]):.1f}",
        f"{100 * np.mean([c.within_bound for c in cases]):.0f} %",
        efficient_share(cases),
    ]


def efficient_share(cases: list[Case]) -> str:
    """The share within the fixed limits an efficient estimator would expect on these motions
    (mean of each one's probability), modelling the target as planes / given its exact shape."""
    shares = [
        100 * np.mean([c.bound.get(key, np.nan) for c in cases])
        for key in ("efficient_within_limits", "known_shape_within_limits")
    ]
    return " / ".join(f"{v:.0f} %" for v in shares)


def per_shape(cases: list[Case]) -> list[list[object]]:
    """One row per shape, both ranges: the issue's goals are per shape."""
    rows: list[list[object]] = []
    for name in dict.fromkeys(c.shape for c in cases):
        mine = [c for c in cases if c.shape == name]
        rows.append([
            name,
            len(mine),
            f"{100 * np.mean([c.within_limits for c in mine]):.0f} %",
            efficient_share(mine),
            sum(not c.within_limits and not c.flagged for c in mine),
            f"{100 * np.mean([c.worst_sigma > 3 for c in mine]):.1f} %",
            f"{rms_ratio(mine, 'sigma'):.2f}",
            f"{rms_ratio(mine, 'bound'):.2f}",
            f"{max(c.seconds for c in mine):.1f}",
        ])  # fmt: skip
    return rows


def rms_ratio(cases: list[Case], over: Literal["sigma", "bound"]) -> float:
    """The RMS over the cases and the four parameters of the error over its reported sigma
    (``over="sigma"``: about 1 when the sigmas are honest, below when cautious) or over its
    bound (``"bound"``: about 1 for an efficient estimator; what the estimator's errors are)."""
    ratios = [
        c.errors[f"{p}_sigma"] if over == "sigma" else c.errors[f"{p}_{UNITS[p]}"] / c.bound[f"{p}_{UNITS[p]}"]
        for c in cases
        for p in PARAMS
    ]
    return float(np.sqrt(np.nanmean(np.square(ratios))))


def sigma_over_bound(c: Case) -> float:
    """The median over the four parameters of the reported sigma over the bound: how far the
    estimate's own precision is from what the data allow (1 for an efficient estimator)."""
    return float(np.nanmedian([c.errors[f"{p}_sd"] / c.bound[f"{p}_{UNITS[p]}"] for p in PARAMS]))


def beyond_bound(cases: list[Case]) -> list[list[object]]:
    """One row per case outside max(floor, 3 x bound): errors, reported sigmas, bounds, flag."""
    rows: list[list[object]] = []
    for c in cases:
        if c.within_bound:
            continue
        # "*": the parameter beyond its max(floor, 3 x bound).
        cells = [
            f"{c.errors[f'{p}_{UNITS[p]}']:.4f} / {c.errors[f'{p}_sd']:.4f} / {c.bound[f'{p}_{UNITS[p]}']:.4f}"
            + ("*" if c.errors[f"{p}_{UNITS[p]}"] > c.bound_limits[p] else " ")
            for p in PARAMS
        ]
        rows.append([c.shape, f"{c.distance_m:g}", c.seed, *cells, "+".join(c.flags) or "none"])
    return rows


def plot(cases: list[Case], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = sorted({c.shape for c in cases})
    fig, ax = plt.subplots(figsize=(9, 4.5))
    for i, name in enumerate(names):
        ys = [c.worst_sigma for c in cases if c.shape == name]
        colors = ["tab:red" if not c.within_limits else "tab:blue" for c in cases if c.shape == name]
        ax.scatter(np.full(len(ys), i) + np.random.default_rng(i).uniform(-0.2, 0.2, len(ys)), ys, c=colors, s=14)
    ax.axhline(3, color="grey", ls="--", lw=1)
    ax.set_yscale("log")
    ax.set_xticks(range(len(names)), names)
    ax.set_ylabel("worst |error| / reported sigma (4 parameters)")
    ax.set_title("Dense frames of real shapes (red: outside 0.05 deg/s or 0.1 deg)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def report(cases: list[Case], stem: str) -> None:
    """The table per shape and range, the cases beyond the bound; ``stem``.json and .png."""
    rows = []
    for name in dict.fromkeys(c.shape for c in cases):
        for distance in sorted({c.distance_m for c in cases if c.shape == name}):
            rows.append(summary([c for c in cases if c.shape == name and c.distance_m == distance]))
    header = ["shape", "range m", "cases", "within limits", "misses flagged check/unrel./imprec.", "unflagged",
              "all <= 3 sigma", "hits flagged", "> 5 sigma unflagged", "points used", "s median / max",
              "3x bound > limits", "sigma / bound", "within max(floor, 3x bound)",
              "efficient: within limits (planes / known shape)"]  # fmt: skip
    print(table(rows, header))
    print(
        "\nPer shape, both ranges, against the issue's goals (>= 95 % within limits, no miss unflagged, "
        "<= 5 % over 3 sigma, <= 20 s):"
    )
    print(table(per_shape(cases), ["shape", "cases", "within limits", "efficient estimator would expect "
                                   "(planes / known shape)", "unflagged misses", "over 3 sigma",
                                   "rms error / sigma", "rms error / bound", "max s"]))  # fmt: skip
    beyond = beyond_bound(cases)
    print(
        f"\n{len(beyond)} of {len(cases)} cases outside max(floor, 3x bound); "
        "error / reported sigma / bound (deg, deg/s), * beyond max(floor, 3x bound)"
    )
    if beyond:
        print(table(beyond, ["shape", "range m", "seed", *PARAMS, "flags"]))
    out = out_dir()
    (out / f"{stem}.json").write_text(json.dumps([asdict(c) for c in cases], indent=1))
    plot(cases, out / f"{stem}.png")
    print(f"wrote {out / stem}.json and .png")


def start_run(shapes: list[str]) -> list[str]:
    """Print the machine, load Open3D and return ``shapes`` less the Hubble mesh when its file is
    absent (saying so). Open3D's import (about 1.5 s) is paid once per worker, not per job: not in
    the first case's time."""
    print(machine())
    if "hubble" in shapes and not HUBBLE.is_file():
        print(f"skipping hubble: {HUBBLE} is absent")
        shapes = [s for s in shapes if s != "hubble"]
    load_open3d()
    return shapes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--motions", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=0, help="seeds first-seed .. first-seed + motions - 1")
    parser.add_argument("--no-beams", action="store_true", help="without thin members as lines (DenseConfig.beams)")
    parser.add_argument("--no-grazing", action="store_true", help="without the grazing hits (DenseConfig.grazing)")
    parser.add_argument("--distances", type=float, nargs="+", default=[50.0, 100.0])
    parser.add_argument("--size", type=int, default=512, help="lines and pixels per frame")
    parser.add_argument("--shapes", nargs="+", default=["box", *PARAMETRIC, "hubble"])
    parser.add_argument("--stem", default="real_shapes", help="name of the JSON and plot in bench/out")
    parser.add_argument("--report", nargs="+", type=Path, help="only report saved runs' JSON (e.g. split by shapes)")
    parser.add_argument("--rebound", action="store_true", help="with --report: compute the saved cases' bound anew")
    args = parser.parse_args()
    if args.report:
        saved = [Case(**c) for path in args.report for c in json.loads(path.read_text())]
        report([rebound(c, args.size) for c in saved] if args.rebound else saved, args.stem)
        return
    args.shapes = start_run(args.shapes)
    dense = DenseConfig(beams=not args.no_beams, grazing=not args.no_grazing)
    options = FramesOptions(dense=dense) if dense != DenseConfig() else None
    cases: list[Case] = []
    for name in args.shapes:
        for distance in args.distances:
            seeds = range(args.first_seed, args.first_seed + args.motions)
            cases += [one(name, distance, seed, args.size, options) for seed in seeds]
            print(f"  {name} at {distance:g} m done ({os.getloadavg()[0]:.1f} load average)", flush=True)
    report(cases, args.stem)
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    print(f"peak memory of the whole run: {peak_gb:.2f} GB")


if __name__ == "__main__":
    main()
