"""marker-pose-graph benchmark: ours (per-frame identification + GTSAM graph, with and without the
constant-velocity prior) beside the paper's method (VC chain + pose graph), on the same
simulated cases; then timings for 500 and 10,000 frames.

    PYTHONPATH=service:client python -m bench.marker_pose.run [--seeds 5] [--levels ABC] [--no-timing]

Prints one table per layout mode (level A), one for tags (levels B and C, ``tags.py``) and writes
plots to bench/out/.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

from tumblescan.marker_pose.estimate import estimate_poses
from tumblescan.marker_pose.evaluate import evaluate
from tumblescan.marker_pose.markers_io import markers_from_json
from tumblescan.marker_pose.options import MarkerPoseOptions
from tumblescan.marker_pose.simulate import SimConfig, simulate

from ..common import machine, out_dir, table

METHODS: dict[str, dict[str, Any]] = {
    "ours": {},
    "ours+cv": {"motion_prior": "constant_velocity"},
    "paper": {"method": "paper"},
}
CASES = [("kite", "paper"), ("box", "paper"), ("kite", "tumble"), ("box", "tumble")]
GOALS = "goals (tier 1): ratio <= 1.3, no drift, coverage >= 0.98, worst <= 8, NEES/6 in 0.25-4"


def accuracy(seeds: int, with_layout: bool) -> list[dict[str, Any]]:
    runs = []
    for target, motion in CASES:
        for seed in range(seeds):
            sim = simulate(SimConfig(target=target, motion=motion, with_layout=with_layout), seed)
            data = markers_from_json(sim.document())
            truth = sim.truth()
            for name, opts in METHODS.items():
                if name == "paper" and not with_layout:
                    continue  # the paper's method needs the layout's marker order
                started = time.perf_counter()
                result = estimate_poses(data, MarkerPoseOptions(**opts))
                ev = evaluate(result, truth)
                runs.append(
                    {
                        "case": f"{target}/{motion}",
                        "seed": seed,
                        "method": name,
                        "time_s": time.perf_counter() - started,
                        **ev,
                    }
                )
    return runs


def summary(runs: list[dict[str, Any]]) -> list[list[object]]:
    rows: list[list[object]] = []
    for name in METHODS:
        for case in sorted({r["case"] for r in runs}):
            sel = [r for r in runs if r["method"] == name and r["case"] == case]
            if not sel:
                continue
            pass_ = sum(
                r["ratio"] <= 1.3
                and r["coverage"] >= 0.98
                and r["worst_mahalanobis"] <= 8
                and 0.25 <= r["nees_over_6"] <= 4
                for r in sel
            )
            rows.append(
                [
                    name,
                    case,
                    len(sel),
                    f"{np.median([r['ratio'] for r in sel]):.2f} / {max(r['ratio'] for r in sel):.2f}",
                    f"{min(r['coverage'] for r in sel):.3f}",
                    f"{max(r['worst_mahalanobis'] for r in sel):.1f}",
                    f"{np.median([r['nees_over_6'] for r in sel]):.2f}",
                    f"{max(abs(r['drift_deg']) for r in sel):.2f} / {max(abs(r['drift_mm']) for r in sel):.1f}",
                    f"{_median(sel, 'rot_3sigma_deg'):.2f} / {_median(sel, 'pos_3sigma_mm'):.1f}",
                    f"{pass_}/{len(sel)}",
                ]
            )
    return rows


def _median(runs: list[dict[str, Any]], key: str) -> float:
    return float(np.median([r[key] for r in runs]))


HEADER = [
    "method",
    "case",
    "n",
    "ratio med/max",
    "cov min",
    "worst",
    "NEES/6 med",
    "drift deg/mm max",
    "3sig deg/mm med",
    "tier1 pass",
]


def timings() -> list[list[object]]:
    """500 frames x 4 markers: identification + per-frame Kabsch alone, then the whole estimate
    (graph and marginals); the same for 10,000 frames. Wall and CPU seconds (the machine is shared:
    CPU time is what the estimate itself costs)."""
    from tumblescan.marker_pose.graph import frame_covariances
    from tumblescan.marker_pose.identify import associate
    from tumblescan.marker_pose.labelling import Gates

    rows: list[list[object]] = []
    estimate_poses(markers_from_json(simulate(SimConfig(frames=50), 1).document()))  # imports, once
    for frames in (500, 10_000):
        sim = simulate(SimConfig(target="kite", frames=frames, resets=3, glints=0, reflections=0), 11)
        data = markers_from_json(sim.document())
        assert data.layout is not None
        wall, cpu = time.perf_counter(), time.process_time()
        a = associate(data, data.layout.p_body_m, Gates.make(data.point_sigma_m, 5.0))
        frame_covariances(a.R, data.obs_frame, a.obs_marker, data.layout.p_body_m, data.point_sigma_m, a.measured)
        per_frame = (time.perf_counter() - wall, time.process_time() - cpu)
        for name, opts in METHODS.items():
            wall, cpu = time.perf_counter(), time.process_time()
            estimate_poses(data, MarkerPoseOptions(**opts))
            rows.append(
                [
                    frames,
                    name,
                    f"{per_frame[0]:.2f} / {per_frame[1]:.2f}",
                    f"{time.perf_counter() - wall:.2f} / {time.process_time() - cpu:.2f}",
                ]
            )
    return rows


def plot(runs: list[dict[str, Any]], name: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    for ax, key, goal in zip(axes, ("ratio", "worst_mahalanobis", "nees_over_6"), (1.3, 8.0, 4.0), strict=True):
        labels, data = [], []
        for m in METHODS:
            vals = [r[key] for r in runs if r["method"] == m]
            if vals:
                labels.append(m)
                data.append(vals)
        ax.boxplot(data, tick_labels=labels)
        ax.axhline(goal, color="r", ls="--")
        ax.set_yscale("log")
        ax.set_title(key)
    fig.suptitle(f"marker-pose-graph, {name}")
    fig.tight_layout()
    fig.savefig(out_dir() / f"marker_pose_{name}.png", dpi=100)


def error_plot() -> None:
    """Rotation error over time of one paper-like kite run, for each method, beside the per-frame
    3-sigma bound: what drift would look like (there is none in ours)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tumblescan.marker_pose.geometry import log_so3, matrix_from_quat_wxyz

    sim = simulate(SimConfig(target="kite", motion="paper"), 0)
    data = markers_from_json(sim.document())
    truth = {f["frame"]: f for f in sim.truth()["frames"]}
    fig, ax = plt.subplots(figsize=(12, 4))
    for name, opts in METHODS.items():
        result = estimate_poses(data, MarkerPoseOptions(**opts))
        t, err = [], []
        for p in result.poses:
            if p.status == "measured" and p.T_world_body is not None:
                R_t = matrix_from_quat_wxyz(np.array(truth[p.frame]["q_wxyz"]))
                R_e = matrix_from_quat_wxyz(np.array(p.T_world_body.q_wxyz))
                t.append(p.t)
                err.append(np.degrees(np.linalg.norm(log_so3(R_t @ R_e.T))))
        ax.plot(t, err, lw=0.8, label=name)
    bound = [
        (f["t"], np.degrees(3 * np.sqrt(np.trace(np.array(f["crlb"])[:3, :3]))))
        for f in truth.values()
        if f["crlb"] is not None
    ]
    ax.plot(*zip(*bound, strict=True), "k--", lw=0.8, label="per-frame bound, 3 sigma (norm)")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("rotation error [deg]")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out_dir() / "marker_pose_error_over_time.png", dpi=100)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--no-timing", action="store_true")
    parser.add_argument("--timing-only", action="store_true")
    parser.add_argument("--levels", default="ABC", help="which levels to run (A: markers, B: tags, C: images)")
    parser.add_argument("--seeds-c", type=int, default=3, help="seeds per motion at level C (rendering is slow)")
    args = parser.parse_args()
    print(f"marker-pose-graph bench on {machine()}\n{GOALS}")
    if not args.timing_only and ("B" in args.levels or "C" in args.levels):
        from .tags import HEADER as TAG_HEADER
        from .tags import level_b, level_c
        from .tags import summary as tag_summary

        runs = level_b(args.seeds) if "B" in args.levels else []
        runs += level_c(args.seeds_c) if "C" in args.levels else []
        print(
            "\ntags (B: 500 frames of detections at 0.25 px; C: 30 frames of 4 x 1024 px images), "
            "ratio against the per-frame tag bound (goal <= 1.3)\n" + table(tag_summary(runs), TAG_HEADER)
        )
        if "B" in args.levels and not args.no_timing:
            from .tags import timings_b

            header = ["frames", "detections", "method", "read wall/cpu", "estimate wall/cpu"]
            print("\ntimings [s] (level B, tagged box)\n" + table(timings_b(), header))
    for with_layout in () if args.timing_only or "A" not in args.levels else (True, False):
        name = "given layout" if with_layout else "bootstrapped layout"
        runs = accuracy(args.seeds, with_layout)
        print(f"\n{name} (500 frames, 50 Hz, sigma 2.9 mm, 3 resets = 4 segments)\n" + table(summary(runs), HEADER))
        plot(runs, name.replace(" ", "_"))
    if "A" in args.levels:
        error_plot()
    if not args.no_timing and "A" in args.levels:
        print(
            "\ntimings [s] (kite, 4 markers)\n"
            + table(timings(), ["frames", "method", "per-frame only wall/cpu", "total wall/cpu"])
        )


if __name__ == "__main__":
    main()
