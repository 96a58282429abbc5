"""Speed on this machine: time per estimate (auto path and forced swarm), rectification of
4 million points, peak memory.

Requirements: median <= 50 ms (auto) and <= 300 ms (swarm); 4 M points rectified < 1 s.
Usage: python -m bench.linescan.speed [--scenarios 100]
"""

from __future__ import annotations

import argparse
import resource
import time

import numpy as np

from tumblescan import EstimateOptions, estimate_motion, random_motion, rectify

from ..common import machine, out_dir, scenario, table


def time_estimates(n: int, strategy: str) -> np.ndarray:
    data = [scenario(seed, noise=True)[1] for seed in range(n)]
    estimate_motion(data[0], EstimateOptions(strategy=strategy))  # warm caches and imports
    out = []
    for tracks in data:
        t = time.perf_counter()
        estimate_motion(tracks, EstimateOptions(strategy=strategy))
        out.append(time.perf_counter() - t)
    return np.array(out)


def time_rectify(n_points: int, repeats: int = 5) -> np.ndarray:
    rng = np.random.default_rng(0)
    motion = random_motion(rng)
    xyz = rng.normal(size=(n_points, 3)) * 3 + [0, 0, 50]
    t_s = rng.uniform(0, 15, n_points)
    out = []
    for _ in range(repeats):
        t = time.perf_counter()
        rectify(xyz, t_s, motion, to_time_s=0.0)
        out.append(time.perf_counter() - t)
    return np.array(out)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenarios", type=int, default=100)
    args = ap.parse_args()
    print(f"machine: {machine()}")
    auto = time_estimates(args.scenarios, "auto")
    swarm = time_estimates(args.scenarios, "swarm")
    rect = time_rectify(4_000_000)
    rows = [
        [
            "estimate, strategy=auto",
            float(np.median(auto) * 1000),
            float(np.percentile(auto, 90) * 1000),
            "<= 50 ms",
            "0.25 s",
        ],
        [
            "estimate, strategy=swarm",
            float(np.median(swarm) * 1000),
            float(np.percentile(swarm, 90) * 1000),
            "<= 300 ms",
            "2.62 s",
        ],
        ["rectify 4 M points", float(np.median(rect) * 1000), float(np.max(rect) * 1000), "< 1000 ms", "-"],
    ]
    print(table(rows, ["task", "median ms", "p90 / max ms", "requirement", "paper"]))
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak memory (max RSS of this process, including 4 M-point arrays): {peak_mb:.0f} MB")
    _plot(auto, swarm)


def _plot(auto: np.ndarray, swarm: np.ndarray) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    ax.hist(auto * 1000, bins=30, alpha=0.7, label="auto")
    ax.hist(swarm * 1000, bins=30, alpha=0.7, label="swarm")
    ax.set(xlabel="time per estimate (ms)", ylabel="scenarios", title="estimate time, 15 frames, Table 1 noise")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out_dir() / "speed.png", dpi=110)
    print(f"plot: {out_dir() / 'speed.png'}")


if __name__ == "__main__":
    main()
