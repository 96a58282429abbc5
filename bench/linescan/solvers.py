"""Solver comparisons in the manner of the paper's Figs. 3 and 4.

Fig. 3: local solvers started from good initial values (the closed-form cone initializer)
on the pairwise objective (paper eq. 10): Levenberg-Marquardt, trust region (scipy 'trf'),
Nelder-Mead and quasi-Newton (BFGS); plus our default, LM on the maximum-likelihood
objective. Noise-free data; error = largest parameter error against the truth.

Fig. 4: the four swarm variants (pso, tvac, apso, naiwpso), population 100, 35 iterations,
100 runs per motion state with the best and worst 10 (by final fitness) dropped; the mean
best-fitness curve per variant, and how often swarm + LM reaches the truth.

Usage: python -m bench.linescan.solvers [--scenarios 30] [--states 4] [--runs 100]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.optimize import least_squares, minimize

from tumblescan import SwarmConfig
from tumblescan.linescan.initializer import cone_initial
from tumblescan.linescan.sensor import SensorNoise
from tumblescan.linescan.sparse.fit import fit_model
from tumblescan.linescan.sparse.objective import PairwiseProblem
from tumblescan.linescan.sparse.search import swarm_search
from tumblescan.linescan.swarm import VARIANTS
from tumblescan.target.motion import canonical_params

from ..common import machine, out_dir, scenario, table

SUCCESS = 1e-6


def _error(x: np.ndarray, truth: np.ndarray) -> float:
    d = canonical_params(x) - truth
    d[[0, 3]] = np.mod(d[[0, 3]] + np.pi, 2 * np.pi) - np.pi
    return float(np.max(np.abs(d)))


LOCAL = ("LM", "trust region", "Nelder-Mead", "quasi-Newton", "LM (ML objective)")
TIGHT = {"xtol": 1e-15, "ftol": 1e-15, "gtol": 1e-15}


def run_local(name: str, prob: PairwiseProblem, x0: np.ndarray) -> np.ndarray:
    """One local solver from ``x0`` on the pairwise objective (ML for the last one)."""

    def f(x: np.ndarray) -> float:
        r = prob.residuals(x)
        return float(r @ r)

    def g(x: np.ndarray) -> np.ndarray:
        return np.asarray(2 * prob.jacobian(x).T @ prob.residuals(x))

    if name == "LM":
        return np.asarray(least_squares(prob.residuals, x0, jac=prob.jacobian, method="lm", **TIGHT).x)
    if name == "trust region":
        return np.asarray(least_squares(prob.residuals, x0, jac=prob.jacobian, method="trf", **TIGHT).x)
    if name == "Nelder-Mead":
        opts = {"maxiter": 20000, "maxfev": 20000, "xatol": 1e-12, "fatol": 1e-20}
        return np.asarray(minimize(f, x0, method="Nelder-Mead", options=opts).x)
    if name == "quasi-Newton":
        return np.asarray(minimize(f, x0, jac=g, method="BFGS", options={"gtol": 1e-14, "maxiter": 5000}).x)
    fit = fit_model(
        prob.tracks, x0, spin_only=False, objective="ml", noise=SensorNoise(), reference_time_s=prob.reference_time_s
    )
    return fit.x


def local_solvers(n: int) -> dict[str, list[tuple[float, float]]]:
    out: dict[str, list[tuple[float, float]]] = {k: [] for k in LOCAL}
    for seed in range(n):
        motion, tracks = scenario(seed, noise=False)
        T = float(tracks.t_s.min())
        truth = canonical_params(motion.at_reference(T).params())
        x0 = cone_initial(tracks, T).x
        prob = PairwiseProblem(tracks, T)
        for name in LOCAL:
            t = time.perf_counter()
            x = run_local(name, prob, x0)
            out[name].append((time.perf_counter() - t, _error(x, truth)))
    return out


def swarms(states: int, runs: int) -> tuple[dict[str, list[np.ndarray]], dict[str, list[tuple[float, float]]]]:
    curves: dict[str, list[np.ndarray]] = {v: [] for v in VARIANTS}
    outcome: dict[str, list[tuple[float, float]]] = {v: [] for v in VARIANTS}
    for s in range(states):
        motion, tracks = scenario(1000 + s, noise=False)
        T = float(tracks.t_s.min())
        truth = canonical_params(motion.at_reference(T).params())
        for variant in VARIANTS:
            cfg = SwarmConfig(variant=variant)
            results = []
            for run in range(runs):
                t = time.perf_counter()
                sw = swarm_search(tracks, T, cfg, np.random.default_rng(run))
                elapsed = time.perf_counter() - t
                fit = fit_model(tracks, sw.x, spin_only=False, objective="ml", noise=SensorNoise(), reference_time_s=T)
                results.append((sw.history, elapsed, _error(fit.x, truth)))
            # Drop the best and worst 10 % by final fitness, as the paper did.
            results.sort(key=lambda r: r[0][-1])
            k = runs // 10
            kept = results[k : runs - k] if runs >= 10 else results
            curves[variant].append(np.mean([r[0] for r in kept], axis=0))
            outcome[variant] += [(r[1], r[2]) for r in kept]
    return curves, outcome


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenarios", type=int, default=30)
    ap.add_argument("--states", type=int, default=4)
    ap.add_argument("--runs", type=int, default=100)
    args = ap.parse_args()
    print(f"machine: {machine()}")

    loc = local_solvers(args.scenarios)
    print(f"\nFig. 3: local solvers from the cone initializer, {args.scenarios} noise-free scenarios")
    rows = []
    for name, res in loc.items():
        t = np.array([r[0] for r in res]) * 1000
        e = np.array([r[1] for r in res])
        rows.append(
            [
                name,
                float(np.median(t)),
                float(np.max(t)),
                float(np.median(e)),
                float(np.max(e)),
                f"{100 * np.mean(e < SUCCESS):.0f} %",
            ]
        )
    print(table(rows, ["solver", "median ms", "max ms", "median error", "max error", f"error < {SUCCESS:g}"]))

    curves, outcome = swarms(args.states, args.runs)
    print(f"\nFig. 4: swarm variants, {args.states} states x {args.runs} runs (best and worst 10 % dropped), then LM")
    rows = []
    for v in VARIANTS:
        final = np.array([c[-1] for c in curves[v]])
        t = np.array([o[0] for o in outcome[v]]) * 1000
        e = np.array([o[1] for o in outcome[v]])
        at = [float(np.mean([c[i - 1] for c in curves[v]])) for i in (5, 15, 25)]
        rows.append([v, *at, float(np.mean(final)), float(np.median(t)), f"{100 * np.mean(e < SUCCESS):.1f} %"])
    header = ["variant", "fitness @5", "@15", "@25", "@35 (final, m^2)", "median ms/run", "swarm+LM reaches truth"]
    print(table(rows, header))
    _plot(loc, curves)
    print(f"\nplot: {out_dir() / 'solvers.png'}")


def _plot(loc: dict[str, list[tuple[float, float]]], curves: dict[str, list[np.ndarray]]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n_states = len(next(iter(curves.values())))
    fig, axes = plt.subplots(1, 1 + n_states, figsize=(4.2 * (1 + n_states), 4))
    names = list(loc)
    axes[0].boxplot([[r[0] * 1000 for r in loc[n]] for n in names], tick_labels=[n.replace(" (", "\n(") for n in names])
    axes[0].set(yscale="log", ylabel="time (ms)", title="Fig. 3: local solvers")
    axes[0].tick_params(axis="x", labelsize=7)
    for s in range(n_states):
        for v in curves:
            axes[1 + s].semilogy(curves[v][s], label=v)
        axes[1 + s].set(title=f"Fig. 4: state {s + 1}", xlabel="iteration", ylabel="best fitness (m^2)")
        axes[1 + s].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out_dir() / "solvers.png", dpi=100)


if __name__ == "__main__":
    main()
