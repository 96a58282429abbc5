"""Fast tumblers from dense frames: how often the estimate is right beyond the paper's rates.

    python -m bench.linescan.fast_tumbler [--motions 12] [--size 256] [--spin 40 90] [--precession 3 30]

Each motion: random axes (at least 10 deg apart), spin and precession rates uniform in the
given ranges (deg/s), 15 frames of ``size x size`` at 50 m with Table 1 noise and frame
timing (1 s period, 0.5 s scan). At 60 deg/s each frame turns the target by ~65 deg, ~30 of
them while it is scanned, and most pairs of this symmetric target register onto a turned copy.
Prints, per motion, which path found the start (cone consensus or swarm fallback), the
errors, the validation and the time; then the share of motions within the issue's limits
(axes 0.02 deg, rates 0.01 deg/s) and within 10x them (not diverged). Writes
``bench/out/fast_tumbler.json``.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from tumblescan import Scanner, Scene, TimedCloud, assemble_frames, estimate_from_frames, random_motion, simulate_frames
from tumblescan.linescan.truth import errors_against

from ..common import machine, out_dir, table

LIMITS = {"spin_axis_deg": 0.02, "spin_rate_deg_s": 0.01, "precession_axis_deg": 0.02, "precession_rate_deg_s": 0.01}


def one(seed: int, size: int, spin: tuple[float, float], precession: tuple[float, float]) -> dict[str, object]:
    motion = random_motion(np.random.default_rng(seed), spin_rate_deg_s=spin, precession_rate_deg_s=precession)
    sim = simulate_frames(motion, Scene(scanner=Scanner(lines=size, pixels=size)), seed=seed)
    frames = assemble_frames(TimedCloud(sim.xyz_m, sim.t_s, {"frame": sim.frame, "line": sim.line}))
    started = time.perf_counter()
    result = estimate_from_frames(frames)
    err = {k: abs(v) for k, v in errors_against(result, motion).items()}
    return {
        "seed": seed,
        "spin_deg_s": float(np.degrees(motion.spin_rate_rad_s)),
        "precession_deg_s": float(np.degrees(motion.precession_rate_rad_s)),
        "path": result.solver.path.split(" (")[0],
        "errors": err,
        "validated": result.validation.passed,
        "unreliable": any("unreliable" in w for w in result.warnings),
        "time_s": time.perf_counter() - started,
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--motions", type=int, default=12)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--spin", type=float, nargs=2, default=[40.0, 90.0])
    ap.add_argument("--precession", type=float, nargs=2, default=[3.0, 30.0])
    args = ap.parse_args()
    rows = [one(s, args.size, tuple(args.spin), tuple(args.precession)) for s in range(args.motions)]
    keys = list(LIMITS)
    print(
        f"fast tumblers, {args.size} x {args.size}, spin {args.spin} deg/s, precession {args.precession}; {machine()}"
    )
    print(
        table(
            [
                [
                    r["seed"],
                    r["spin_deg_s"],
                    r["precession_deg_s"],
                    r["path"],
                    *(r["errors"].get(k, float("nan")) for k in keys),  # type: ignore[attr-defined]
                    r["validated"],
                    r["unreliable"],
                    r["time_s"],
                ]
                for r in rows
            ],
            ["seed", "spin", "prec", "path", "spin ax", "spin rate", "prec ax", "prec rate", "valid", "flagged", "s"],
        )
    )

    def within(r: dict[str, object], factor: float) -> bool:
        e = r["errors"]
        return all(e.get(k, np.inf) <= factor * v for k, v in LIMITS.items())  # type: ignore[attr-defined]

    n = len(rows)
    print(
        f"within the limits: {sum(within(r, 1) for r in rows)}/{n}; within 10x: {sum(within(r, 10) for r in rows)}/{n}"
    )
    print(f"swarm fallback used: {sum(r['path'] == 'registration+swarm+dense' for r in rows)}/{n}")
    print(
        f"wrong (beyond 10x) and flagged unreliable or failing validation: "
        f"{sum((not within(r, 10)) and (bool(r['unreliable']) or not r['validated']) for r in rows)}"
        f"/{sum(not within(r, 10) for r in rows)}"
    )
    (out_dir() / "fast_tumbler.json").write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
