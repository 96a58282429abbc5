"""Benchmark of the ``bearings`` kind: ours (ML) and the paper's method on the same simulated cases.

Per case (seeded simulations, digest §8): association accuracy on clean target-frames, missed,
false targets, RMS and p99 of the error over the single-frame bound, mean NEES/3, the share of
ambiguous target-frames associated right, and the CPU time for 10 frames including parsing
the JSON text and writing the result JSON, on one core. Then the speed for 10, 100 and 1000 targets,
and a plot of the error against the bound. "ghost reports" are reports
whose pair is a ghost (a non-true pair with χ² ≤ 25), excused from the false targets as the
digest scores them (bench/out/bearings_error_vs_bound.png).

    PYTHONPATH=service:client python -m bench.bearings.run [--quick]
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from tumblescan.bearings.estimate import estimate
from tumblescan.bearings.inputs import load_json, parse_input
from tumblescan.bearings.options import EstimateOptions
from tumblescan.bearings.score import Score, score, score_tracks
from tumblescan.bearings.simulate import SimulationConfig, simulate

OUT = Path(__file__).resolve().parents[1] / "out"


@dataclass(frozen=True)
class Case:
    name: str
    scene: str
    targets: int
    clutter: float = 0.0
    p_miss: float = 0.0
    seeds: int = 5
    rms_goal: float = 1.15


CASES = (
    Case("paper K=5", "paper", 5),
    Case("paper K=5, 20 % clutter, 10 % miss", "paper", 5, 0.2, 0.1),
    Case("close K=6", "close", 6),
    Case("near-collinear K=5", "near-collinear", 5, rms_goal=1.25),
    Case("baseline plane K=5", "baseline-plane", 5),
    Case("similar elevation K=5", "similar-elevation", 5),
    Case("swarm K=100", "swarm", 100),
    Case("LEO K=10", "leo", 10),
    Case("LEO K=100, 20 % clutter, 10 % miss", "leo", 100, 0.2, 0.1),
    Case("swarm K=1000", "swarm", 1000, seeds=3),
    Case("LEO K=1000, 20 % clutter, 10 % miss", "leo", 1000, 0.2, 0.1, seeds=3),
)


METHODS = {
    "ours (ML + multi-frame)": EstimateOptions(),
    "ours (ML, single frame)": EstimateOptions(multi_frame=False),
    "paper": EstimateOptions(method="paper"),
}


def timed_run(text: str, method: str) -> tuple[dict[str, Any], float]:
    """Parse, estimate and write the result JSON; returns the result and the CPU seconds taken
    (what one core spends, unaffected by other processes competing for the shared machine)."""
    start = time.process_time()
    result = estimate(parse_input(load_json(text)), METHODS[method])
    json.dumps(result, allow_nan=False)
    return result, time.process_time() - start


TRACKS: dict[str, tuple[list[float], list[float]]] = {}


def run_case(case: Case, method: str) -> tuple[Score, float, float]:
    """Score over the case's seeds; mean time per 10 frames; worst noise-free error (m). The
    track fits of ours (ML + multi-frame) go to ``TRACKS``."""
    total, times, noise_free = Score(), [], 0.0
    for seed in range(case.seeds):
        config = SimulationConfig(
            scene=case.scene, seed=seed, targets=case.targets, clutter=case.clutter, p_miss=case.p_miss
        )
        sim = simulate(config)
        result, seconds = timed_run(json.dumps(sim.input), method)
        total.add(score(result, sim.truth))
        if method == "ours (ML + multi-frame)":
            r, n = score_tracks(result, sim.truth, min_frames=10)
            TRACKS.setdefault(case.name, ([], []))[0].extend(r)
            TRACKS[case.name][1].extend(n)
        times.append(seconds)
        if method != "paper" and seed == 0:
            clean = score(timed_run(json.dumps(sim.input_noise_free), method)[0], sim.truth)
            if clean.clean_associated != clean.clean:
                noise_free = float("inf")
            elif clean.clean:
                noise_free = max(noise_free, clean.max_error_m)
            else:
                noise_free = float("nan")  # no clean target-frame: every pairing is a perfect ghost
    return total, float(np.mean(times)), noise_free


def pct(x: float) -> str:
    return "-" if np.isnan(x) else f"{100 * x:.2f} %"


def num(x: float, digits: int = 2) -> str:
    return "-" if np.isnan(x) else f"{x:.{digits}f}"


def goals_met(case: Case, s: Score) -> str:
    """The digest's tier-1 goals (one target-frame may always be lost in a small case)."""
    if s.clean < 10:
        return "n/a (no clean targets)"
    n = len(s.ratio)
    rms_cap = max(case.rms_goal, float(np.sqrt(1 + 2.33 * np.sqrt(2 / (3 * n)))))
    lost = s.clean - s.clean_associated
    checks = {
        "assoc": s.association >= 0.995 or lost <= 1,
        "missed": s.missed_share <= 0.005 or s.clean_missed <= 1,
        "false": s.false_share <= 0.01,
        "rms": s.ratio_rms <= rms_cap,
        "p99": s.ratio_p99 <= 2.3,
        "nees": 0.67 <= s.nees_mean <= 1.5,
    }
    failed = [k for k, ok in checks.items() if not ok]
    return "all met" if not failed else "missed: " + ", ".join(failed)


def cpu_run(text: str, method: str) -> tuple[float, float]:
    """CPU and wall seconds of one parse + estimate + JSON."""
    wall = time.perf_counter()
    cpu = timed_run(text, method)[1]
    return cpu, time.perf_counter() - wall


def speed_table(quick: bool) -> list[list[str]]:
    rows = []
    for k, clutter in ((10, 0.0), (100, 0.0), (1000, 0.0), (1000, 0.2)):
        sim = simulate(SimulationConfig(scene="swarm", seed=100 + k, targets=k, clutter=clutter))
        text = json.dumps(sim.input)
        cells = [f"{k}" + (" (20 % clutter)" if clutter else "")]
        for method in METHODS:
            runs = [cpu_run(text, method) for _ in range(1 if quick else 3)]
            cpu, wall = min(r[0] for r in runs), min(r[1] for r in runs)
            cells.append(f"{cpu:.3f} s ({wall:.3f} s)")
        goal = {10: 0.1, 100: 0.3, 1000: 2.0}[k] if not clutter else 3.0
        cells.append(f"<= {goal} s")
        cells.append(f"{peak_mib(text):.0f} MiB")
        rows.append(cells)
    return rows


def peak_mib(text: str) -> float:
    """Peak memory Python and NumPy allocate for one run of ours (tracemalloc)."""
    import tracemalloc

    tracemalloc.start()
    timed_run(text, "ours (ML + multi-frame)")
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak / 2**20


def markdown(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def plot(points: dict[str, tuple[list[float], list[float], list[float]]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 5))
    # The paper's points first, so ours are drawn over them.
    for (label, (bound, error, ratio)), colour in reversed(
        list(zip(points.items(), ("tab:blue", "tab:red"), strict=True))
    ):
        ax1.scatter(bound, error, s=3, alpha=0.3, color=colour, label=label)
        ax2.hist(np.clip(ratio, 0, 6), bins=120, range=(0, 6), density=True, histtype="step", color=colour, label=label)
    lo, hi = 1e-2, 1e4
    ax1.plot([lo, hi], [lo, hi], "k--", lw=1, label="error = bound")
    ax1.plot([lo, hi], [2 * lo, 2 * hi], "k:", lw=1, label="error = 2 x bound")
    ax1.set(xscale="log", yscale="log", xlabel="single-frame bound sqrt(trace CRLB) (m)", ylabel="position error (m)")
    ax1.set_title("Error against the bound (clean target-frames, all cases)")
    ax1.legend(markerscale=4)
    r = np.linspace(0, 6, 400)
    # sqrt(chi2_3 / 3): the ratio of an efficient estimator.
    x = 3 * r**2
    chi3 = np.sqrt(x) * np.exp(-x / 2) / (np.sqrt(2 * np.pi)) * 6 * r
    ax2.plot(r, chi3 / np.trapezoid(chi3, r), "k--", lw=1, label="efficient estimator")
    ax2.set(xlabel="ratio sqrt(e' C^-1 e / 3)", ylabel="density")
    ax2.set_title("Error ratio to the bound")
    ax2.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="fewer seeds, no K=1000 accuracy cases")
    parser.add_argument("--speed", action="store_true", help="only the speed table")
    args = parser.parse_args()
    if args.speed:
        with threadpool_limits(1):
            print(markdown(["targets", *METHODS, "goal (ours)", "peak memory (ours)"], speed_table(quick=False)))
        return
    OUT.mkdir(parents=True, exist_ok=True)
    header = [
        "case",
        "method",
        "clean assoc",
        "missed",
        "false",
        "ghost reports",
        "ratio RMS",
        "ratio p99",
        "NEES/3",
        "ambiguous right",
        "CPU time (10 frames)",
        "noise-free max error",
        "goals",
    ]
    rows = []
    points: dict[str, tuple[list[float], list[float], list[float]]] = {"ours (ML)": ([], [], []), "paper": ([], [], [])}
    plotted = {"ours (ML + multi-frame)": "ours (ML)", "paper": "paper"}
    with threadpool_limits(1):
        warm = json.dumps(simulate(SimulationConfig(scene="leo", targets=2, frames=3)).input)
        for method in METHODS:  # first imports (scipy, pymap3d) out of the timings
            timed_run(warm, method)
        for case in CASES:
            if args.quick and case.targets >= 1000:
                continue
            if args.quick:
                case = Case(**{**case.__dict__, "seeds": 2})
            for method in METHODS:
                label = method
                s, seconds, noise_free = run_case(case, method)
                if method in plotted:
                    points[plotted[method]][0].extend(s.bound_m)
                    points[plotted[method]][1].extend(s.error_m)
                    points[plotted[method]][2].extend(s.ratio)
                amb = s.ambiguous_right / s.ambiguous if s.ambiguous else float("nan")
                rows.append(
                    [
                        case.name,
                        label,
                        pct(s.association),
                        pct(s.missed_share),
                        pct(s.false_share),
                        pct(s.excused_ghosts / s.observable if s.observable else float("nan")),
                        num(s.ratio_rms),
                        num(s.ratio_p99),
                        num(s.nees_mean) if method != "paper" else f"({num(s.nees_mean)})",
                        pct(amb),
                        f"{seconds:.3f} s",
                        f"{noise_free:.1e} m" if method != "paper" and not np.isnan(noise_free) else "-",
                        goals_met(case, s) if method != "paper" else "",
                    ]
                )
                print(" | ".join(rows[-1]), flush=True)
        speed = speed_table(args.quick)
    text = "## Accuracy (per frame, clean target-frames)\n\n" + markdown(header, rows)
    track_rows = [
        [name, str(len(r)), num(float(np.sqrt(np.mean(np.square(r))))), num(float(np.max(r))), num(float(np.mean(n)))]
        for name, (r, n) in TRACKS.items()
        if r
    ]
    text += "\n\n## Track fits (ours; tracks of one true target over all 10 frames; position at t_ref)\n\n"
    text += markdown(["case", "tracks", "ratio RMS (goal <= 0.41)", "ratio max", "NEES/3"], track_rows)
    text += "\n\n## Speed (swarm, 10 frames, one core, parse + estimate + JSON; CPU time (wall time))\n\n"
    text += markdown(["targets", *METHODS, "goal (ours)", "peak memory (ours)"], speed) + "\n"
    print(text)
    (OUT / "bearings.md").write_text(text)
    plot(points, OUT / "bearings_error_vs_bound.png")
    print(f"wrote {OUT / 'bearings.md'} and {OUT / 'bearings_error_vs_bound.png'}")


if __name__ == "__main__":
    main()
