"""Accuracy on the paper's motion grid (w_s 15-37 deg/s, w_p 3-14 deg/s, random axes, 15 frames).

1. Noise-free: every error must be <= 1e-9 (paper: 1e-5) and every scenario validated.
2. Table 1 noise: each quantity's error normalized by the Cramer-Rao bound computed at the
   truth; the RMS of the normalized errors must be <= 1.2 and none beyond 5.
3. Rectification error noise-free (dense frames, estimated motion vs truth) <= 1e-9 m.

Usage: python bench/accuracy.py [--scenarios 200] [--dense 10]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from tumblescan import Scanner, Scene, estimate_motion, rectify, simulate_frames
from tumblescan.linescan.sensor import SensorNoise
from tumblescan.linescan.sparse.objective import MLProblem
from tumblescan.linescan.tracks import Tracks
from tumblescan.linescan.truth import errors_against
from tumblescan.linescan.validation import axis_sigma_rad
from tumblescan.numerics.covariance import covariance
from tumblescan.target.motion import Motion

from ..common import machine, out_dir, scenario, table

QUANTITIES = ("spin_axis_deg", "spin_rate_deg_s", "precession_axis_deg", "precession_rate_deg_s", "center_m")


def crlb(motion: Motion, tracks: Tracks, truth_positions: np.ndarray) -> dict[str, float]:
    """1-sigma Cramer-Rao bounds at the truth, in the result's units."""
    T = float(tracks.t_s.min())
    truth = motion.at_reference(T)
    x = truth.params()
    noise = tracks.sensor or SensorNoise()
    # Weights from the noise-free positions: the bound is a property of the truth.
    clean = Tracks(tracks.track_ids, tracks.track, tracks.t_s, truth_positions, tracks.frame, tracks.sensor)
    problem = MLProblem(clean, noise, T, base=x)
    J = problem.jacobian(problem.pack(x, problem.body_for(x)))
    cov = covariance(J, 9)
    deg = np.degrees
    return {
        "spin_axis_deg": deg(axis_sigma_rad(x, cov, 0, 1)),
        "spin_rate_deg_s": deg(np.sqrt(cov[2, 2])),
        "precession_axis_deg": deg(axis_sigma_rad(x, cov, 3, 4)),
        "precession_rate_deg_s": deg(np.sqrt(cov[5, 5])),
        "center_m": float(np.sqrt(np.trace(cov[6:9, 6:9]))),
    }


def noise_free(n: int) -> list[dict[str, float]]:
    rows = []
    for seed in range(n):
        motion, tracks = scenario(seed, noise=False)
        r = estimate_motion(tracks)
        err = {k: abs(v) for k, v in errors_against(r, motion).items()}
        err["validated"] = float(r.validation.passed)
        err["model_ok"] = float(r.model == "spin-precession")
        rows.append(err)
    return rows


def noisy(n: int) -> tuple[list[dict[str, float]], list[dict[str, float]]]:
    from tumblescan import Scene, simulate_tracks
    from tumblescan.linescan.simulate import random_motion

    normalized, raw = [], []
    for seed in range(n):
        motion = random_motion(np.random.default_rng(seed))
        tracks, truth = simulate_tracks(motion, Scene(), seed=seed)
        r = estimate_motion(tracks)
        err = errors_against(r, motion)
        bound = crlb(motion, tracks, truth.xyz_true_m)
        raw.append({**{k: abs(v) for k, v in err.items()}, "validated": float(r.validation.passed)})
        normalized.append({k: abs(err[k]) / bound[k] for k in QUANTITIES if k in err})
    return normalized, raw


def rectification(n: int) -> list[float]:
    """Mean rectification error (m) of noise-free dense frames with the estimated motion."""
    out = []
    for seed in range(n):
        motion, tracks = scenario(seed, noise=False)
        r = estimate_motion(tracks)
        cloud = simulate_frames(motion, Scene(noise=False, scanner=Scanner(lines=128, pixels=128)), seed=seed)
        T = r.reference_time_s
        est = rectify(cloud.xyz_m, cloud.t_s, r.motion(), to_time_s=T)
        true_at_T = motion.position(cloud.reference_m, np.full(len(cloud.t_s), T))
        out.append(float(np.linalg.norm(est - true_at_T, axis=1).mean()))
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenarios", type=int, default=200)
    ap.add_argument("--dense", type=int, default=10, help="scenarios for the rectification check")
    args = ap.parse_args()
    print(f"machine: {machine()}")
    t0 = time.perf_counter()

    nf = noise_free(args.scenarios)
    print(f"\n1. Noise-free, {len(nf)} scenarios (requirement: every error <= 1e-9, 100 % validated)")
    rows = [[k, float(np.median([r[k] for r in nf])), float(np.max([r[k] for r in nf]))] for k in QUANTITIES]
    print(table(rows, ["quantity", "median |error|", "max |error|"]))
    print(
        f"validated: {100 * np.mean([r['validated'] for r in nf]):.1f} %   "
        f"spin-precession model chosen: {100 * np.mean([r['model_ok'] for r in nf]):.1f} %"
    )

    norm, raw = noisy(args.scenarios)
    print(f"\n2. Table 1 noise, {len(norm)} scenarios (requirement: RMS of error/CRLB <= 1.2, none beyond 5)")
    rows = []
    for k in QUANTITIES:
        z = np.array([r[k] for r in norm])
        e = np.array([r[k] for r in raw])
        rows.append(
            [k, float(np.sqrt(np.mean(e**2))), float(np.sqrt(np.mean(z**2))), float(z.max()), int((z > 5).sum())]
        )
    print(table(rows, ["quantity", "RMSE", "RMS(err/CRLB)", "max err/CRLB", "beyond 5"]))
    print(f"validated: {100 * np.mean([r['validated'] for r in raw]):.1f} %")

    rect = rectification(args.dense)
    print(f"\n3. Rectification, noise-free, {len(rect)} scenarios (requirement: <= 1e-9 m)")
    print(f"mean point error: median {np.median(rect):.3g} m, max {np.max(rect):.3g} m")

    _plot(nf, norm)
    print(f"\ntotal {time.perf_counter() - t0:.1f} s; plot: {out_dir() / 'accuracy.png'}")


def _plot(nf: list[dict[str, float]], norm: list[dict[str, float]]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    for k in QUANTITIES:
        axes[0].semilogy(sorted(max(r[k], 1e-18) for r in nf), label=k)
    axes[0].axhline(1e-9, color="k", ls="--", lw=1)
    axes[0].set(title="noise-free: sorted |error| per scenario", xlabel="scenario (sorted)", ylabel="|error|")
    axes[0].legend(fontsize=7)
    for k in QUANTITIES:
        axes[1].hist([r[k] for r in norm], bins=40, range=(0, 5), histtype="step", label=k)
    axes[1].set(title="Table 1 noise: |error| / CRLB", xlabel="|error| / sigma_CRLB", ylabel="scenarios")
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out_dir() / "accuracy.png", dpi=110)


if __name__ == "__main__":
    main()
