"""Dense frames end to end: accuracy against truth and against corner tracks, rectification
error due to the motion estimate, time per stage and peak memory of a whole job.

    python -m bench.linescan.dense [--motions 30] [--distances 50 100]

Each motion: simulate 15 frames of 512 x 512 (Table 1 scanner and noise), write them as a
binary PLY, then time a whole job as the worker runs it (read, assemble, estimate, rectify,
write). The same motion's corner tracks are estimated beside it. Prints tables and writes
``bench/out/dense.json`` and ``bench/out/dense.png`` (distorted vs rectified, and errors).
"""

from __future__ import annotations

import argparse
import json
import resource
import tempfile
import time
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from tumblescan import (
    Scene,
    TimedCloud,
    estimate_from_frames,
    estimate_motion,
    random_motion,
    read_frames,
    rectify,
    simulate_frames,
    simulate_tracks,
    write_ply,
)
from tumblescan.linescan.result import MotionResult

from ..common import machine, out_dir, table
from .dense_bound import dense_bound, fitted_hits


def errors(r: MotionResult, truth: object) -> dict[str, float]:
    from tumblescan import Motion

    assert isinstance(truth, Motion)
    t = truth.canonical().at_reference(r.reference_time_s)

    def ang(a: object, b: object) -> float:
        return float(np.degrees(np.arccos(np.clip(np.dot(a, b), -1, 1))))  # type: ignore[call-overload]

    u = r.uncertainty
    e = {
        "spin_axis_deg": ang(r.spin.axis, t.spin_axis),
        "spin_rate_deg_s": abs(r.spin.rate_deg_s - np.degrees(t.spin_rate_rad_s)),
        "precession_axis_deg": ang(r.precession.axis, t.precession_axis) if r.precession.axis else float("nan"),
        "precession_rate_deg_s": abs(r.precession.rate_deg_s - np.degrees(t.precession_rate_rad_s)),
    }
    e["spin_axis_sd"] = u.spin_axis_deg
    e["spin_rate_sd"] = u.spin_rate_deg_s
    e["precession_axis_sd"] = u.precession_axis_deg or float("nan")
    e["precession_rate_sd"] = u.precession_rate_deg_s
    e["spin_axis_sigma"] = e["spin_axis_deg"] / u.spin_axis_deg
    e["spin_rate_sigma"] = e["spin_rate_deg_s"] / u.spin_rate_deg_s
    e["precession_axis_sigma"] = e["precession_axis_deg"] / (u.precession_axis_deg or float("nan"))
    e["precession_rate_sigma"] = e["precession_rate_deg_s"] / u.precession_rate_deg_s
    return e


SD_KEYS = ("spin_axis_sd", "spin_rate_sd", "precession_axis_sd", "precession_rate_sd")


@dataclass
class Run:
    """One motion: the whole job's time and stages, dense and corner errors, the bound."""

    seed: int
    distance_m: float
    points: int
    total_s: float
    stages_s: dict[str, float]
    dense: dict[str, float]
    dense_validated: bool | None
    bound: dict[str, float]
    # The bound of the hits in the surfels the fit can use, and their share of all hits.
    bound_fitted: dict[str, float]
    fitted_share: float
    corner: dict[str, float]
    rectification_error_m: float
    warnings: list[str]
    # Seed 0 only: the distorted and rectified points for the plot.
    sample: tuple[NDArray[np.float64], NDArray[np.float64]] | None = field(default=None, repr=False)

    def method(self, name: str) -> dict[str, float]:
        return self.dense if name == "dense" else self.corner


def one(seed: int, distance_m: float, workdir: Path) -> Run:
    motion = random_motion(np.random.default_rng(seed), distance_m=distance_m)
    scene = Scene()
    sim = simulate_frames(motion, scene, seed=seed)
    path = workdir / f"frames-{seed}.ply"
    write_ply(path, TimedCloud(sim.xyz_m, sim.t_s, {"frame": sim.frame, "line": sim.line}))
    # The whole job, stage by stage, as the worker runs it: the time from one progress report
    # to the next belongs to the stage the first one announced.
    stages: dict[str, float] = {}
    mark = time.perf_counter()
    started = mark
    current = "reading+assembling"

    def progress(stage: str, fraction: float) -> None:
        nonlocal mark, current
        now = time.perf_counter()
        stages[current] = stages.get(current, 0.0) + now - mark
        mark, current = now, stage

    frames = read_frames(path)
    progress("preparing", 0)
    result = estimate_from_frames(frames, progress=progress)
    progress("rectifying+writing", 0)
    xyz = rectify(frames.cloud.xyz_m, frames.cloud.t_s, result.motion(), to_time_s=result.reference_time_s)
    write_ply(workdir / "rectified.ply", TimedCloud(xyz, frames.cloud.t_s, frames.cloud.fields))
    progress("done", 0)
    total = time.perf_counter() - started
    # Rectification error due to the motion: the same observed points rectified with the truth.
    T = result.reference_time_s
    true_xyz = rectify(frames.cloud.xyz_m, frames.cloud.t_s, motion, to_time_s=T)
    rect_err = float(np.mean(np.linalg.norm(xyz - true_xyz, axis=1)))
    bound = dense_bound(motion, scene, sim, T)
    fitted = fitted_hits(motion, scene, sim, T)
    tracks, _ = simulate_tracks(motion, scene, seed=seed)
    corner = estimate_motion(tracks)
    return Run(
        seed=seed,
        distance_m=distance_m,
        points=len(frames.cloud),
        total_s=total,
        stages_s=stages,
        dense=errors(result, motion),
        dense_validated=result.validation.passed,
        bound=bound,
        bound_fitted=dense_bound(motion, scene, sim, T, hits=fitted),
        fitted_share=float(np.mean(fitted)),
        corner=errors(corner, motion),
        rectification_error_m=rect_err,
        warnings=result.warnings,
        sample=(sim.xyz_m, xyz) if seed == 0 else None,
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--motions", type=int, default=30)
    ap.add_argument("--distances", type=float, nargs="+", default=[50.0, 100.0])
    args = ap.parse_args()
    rows: list[Run] = []
    with tempfile.TemporaryDirectory() as tmp:
        for distance in args.distances:
            for seed in range(args.motions):
                row = one(seed, distance, Path(tmp))
                d = row.dense
                print(
                    f"{distance:.0f} m seed {seed}: {row.total_s:.1f} s, spin {d['spin_rate_deg_s']:.4f} deg/s, "
                    f"prec {d['precession_rate_deg_s']:.4f} deg/s, axes {d['spin_axis_deg']:.4f} "
                    f"{d['precession_axis_deg']:.4f} deg, rect {row.rectification_error_m * 1000:.2f} mm",
                    flush=True,
                )
                rows.append(row)
    report(rows, args.distances)


def report(rows: list[Run], distances: list[float]) -> None:
    keys = ("spin_axis_deg", "spin_rate_deg_s", "precession_axis_deg", "precession_rate_deg_s")
    limits = {
        "spin_axis_deg": 0.02,
        "spin_rate_deg_s": 0.01,
        "precession_axis_deg": 0.02,
        "precession_rate_deg_s": 0.01,
    }
    out = []
    for distance in distances:
        sel = [r for r in rows if r.distance_m == distance]
        for method in ("dense", "corner"):
            errs = {k: np.array([r.method(method)[k] for r in sel]) for k in keys}
            within = np.mean(np.all([errs[k] <= limits[k] for k in keys], axis=0))
            sig = {
                k: np.array([r.method(method)[k.replace("_deg_s", "_sigma").replace("_deg", "_sigma")] for r in sel])
                for k in keys
            }
            out.append(
                [f"{distance:.0f} m", method]
                + [f"{np.median(errs[k]):.4f} / {np.percentile(errs[k], 95):.4f}" for k in keys]
                + [f"{np.sqrt(np.nanmean(np.concatenate([sig[k] ** 2 for k in keys]))):.2f}", f"{100 * within:.0f} %"]
            )
    print_bound(rows, distances, limits)
    print_restated(rows, distances, limits)
    print(f"\nDense frames vs corner tracks ({len(rows)} runs; {machine()}); errors median / p95")
    print(table(out, ["distance", "method", *keys, "RMS err/sigma", "all within target"]))
    sd_rows = []
    for distance in distances:
        sel = [r for r in rows if r.distance_m == distance]
        for method in ("dense", "corner"):
            sds = [np.array([r.method(method)[k] for r in sel]) for k in SD_KEYS]
            sd_rows.append(
                [f"{distance:.0f} m", method] + [f"{np.median(v):.4f} / {np.percentile(v, 95):.4f}" for v in sds]
            )
    print("\nReported 1-sigma uncertainty (the bound for the data each method used), median / p95")
    print(table(sd_rows, ["distance", "method", *SD_KEYS]))
    stage_rows = []
    for distance in distances:
        sel = [r for r in rows if r.distance_m == distance]
        names = list(dict.fromkeys(k for r in sel for k in r.stages_s))
        for n in names:
            v = [r.stages_s.get(n, 0.0) for r in sel]
            stage_rows.append([f"{distance:.0f} m", n, f"{np.median(v):.2f}", f"{np.max(v):.2f}"])
        tot = [r.total_s for r in sel]
        rect = [r.rectification_error_m for r in sel]
        pts = [r.points for r in sel]
        stage_rows.append([f"{distance:.0f} m", "WHOLE JOB", f"{np.median(tot):.2f}", f"{np.max(tot):.2f}"])
        print(
            f"{distance:.0f} m: points per job median {int(np.median(pts))}; rectification error due to the motion "
            f"mean {np.mean(rect) * 1000:.2f} mm, max {np.max(rect) * 1000:.2f} mm; validated "
            f"{sum(bool(r.dense_validated) for r in sel)}/{len(sel)}"
        )
    print(table(stage_rows, ["distance", "stage", "median s", "max s"]))
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")
    dump = [{f.name: getattr(r, f.name) for f in fields(r) if f.name != "sample"} for r in rows]
    (out_dir() / "dense.json").write_text(json.dumps(dump, indent=1, default=float))
    plot(rows)


def efficient_share(bound: dict[str, float], limits: dict[str, float]) -> float:
    """Chance that an estimator reaching the bound meets every limit: a rate's error is normal
    with sd ``b``; an axis error is 2-D with total sd ``b`` (Rayleigh, ``1 - exp(-L^2 / b^2)``)."""
    from scipy.stats import norm

    p = 1.0
    for k, limit in limits.items():
        b = bound[k]
        p *= 1 - np.exp(-(limit**2) / b**2) if "axis" in k else 2 * norm.cdf(limit / b) - 1
    return float(p)


def print_bound(rows: list[Run], distances: list[float], limits: dict[str, float]) -> None:
    """The dense Cramer-Rao bound (bench/dense_bound.py) against the targets and the errors."""
    keys = list(limits)
    out = []
    for distance in distances:
        sel = [r for r in rows if r.distance_m == distance]
        b = {k: np.array([r.bound[k] for r in sel]) for k in keys}
        e = {k: np.array([r.dense[k] for r in sel]) for k in keys}
        bf = {k: np.array([r.bound_fitted[k] for r in sel]) for k in keys}
        feasible = np.mean(np.all([2 * b[k] <= limits[k] for k in keys], axis=0))
        expected = np.mean([efficient_share(r.bound, limits) for r in sel])
        within = np.mean(np.all([e[k] <= limits[k] for k in keys], axis=0))
        out.append(
            [f"{distance:.0f} m"]
            + [f"{np.median(b[k]):.4f} / {np.percentile(b[k], 95):.4f}" for k in keys]
            + [f"{np.sqrt(np.mean(np.concatenate([(e[k] / b[k]) ** 2 for k in keys]))):.2f}"]
            + [f"{np.mean([r.fitted_share for r in sel]):.2f}"]
            + [f"{np.median(np.concatenate([bf[k] / b[k] for k in keys])):.2f}"]
            + [f"{np.sqrt(np.mean(np.concatenate([(e[k] / bf[k]) ** 2 for k in keys]))):.2f}"]
            + [f"{100 * feasible:.0f} %", f"{100 * expected:.0f} %", f"{100 * within:.0f} %"]
        )
    print("\nCramer-Rao bound of dense frames (1 sigma, median / p95), and what it allows")
    print(
        table(
            out,
            [
                "distance",
                *keys,
                "RMS err/bound",
                "hits in fitted surfels",
                "their bound/bound",
                "RMS err/their bound",
                "2 bound within targets",
                "expected within (efficient)",
                "within",
            ],
        )
    )


def print_restated(rows: list[Run], distances: list[float], limits: dict[str, float]) -> None:
    """Shares of motions meeting the targets as stated, and as the bound allows: every parameter
    within its limit or within ``f`` times its dense bound; and within 3 of the reported sigmas
    (whether the uncertainty a user reads can be trusted)."""
    keys = list(limits)
    out = []
    for distance in distances:
        sel = [r for r in rows if r.distance_m == distance]
        e = np.array([[r.dense[k] for k in keys] for r in sel])
        b = np.array([[r.bound[k] for k in keys] for r in sel])
        sd = np.array([[r.dense[k.replace("_deg_s", "_sd").replace("_deg", "_sd")] for k in keys] for r in sel])
        met = e <= np.array([limits[k] for k in keys])
        out.append(
            [f"{distance:.0f} m", f"{100 * np.mean(np.all(met, axis=1)):.0f} %"]
            + [f"{100 * np.mean(np.all(met | (e <= f * b), axis=1)):.0f} %" for f in (2, 3)]
            + [f"{100 * np.mean(np.all(e <= 3 * sd, axis=1)):.0f} %"]
        )
    print("\nShare of motions: all four within the targets; each within its target or f x its bound; within 3 sigma")
    print(table(out, ["distance", "within targets", "or 2 x bound", "or 3 x bound", "within 3 reported sigma"]))


def plot(rows: list[Run]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sample = next((r.sample for r in rows if r.sample is not None), None)
    fig, ax = plt.subplots(1, 3, figsize=(16, 5))
    if sample is not None:
        raw, rect = sample
        step = max(1, len(raw) // 40000)
        ax[0].scatter(raw[::step, 0], raw[::step, 1], s=0.2, c="tab:red")
        ax[0].set_title("distorted (all frames, sensor x-y)")
        ax[1].scatter(rect[::step, 0], rect[::step, 1], s=0.2, c="tab:blue")
        ax[1].set_title("rectified to the reference time")
        for a in ax[:2]:
            a.set_aspect("equal")
            a.set_xlabel("x (m)")
            a.set_ylabel("y (m)")
    for method, marker in (("dense", "o"), ("corner", "x")):
        v = [r.method(method)["spin_rate_deg_s"] for r in rows]
        ax[2].scatter(range(len(v)), v, marker=marker, label=f"{method} spin-rate error")
    ax[2].axhline(0.01, color="k", lw=0.8, ls="--", label="target 0.01 deg/s")
    ax[2].set_yscale("log")
    ax[2].set_xlabel("run")
    ax[2].legend()
    fig.tight_layout()
    fig.savefig(out_dir() / "dense.png", dpi=110)


if __name__ == "__main__":
    main()
