"""Which robust loss the dense fit should minimise: each loss's optimum from the truth, per shape.

    python -m bench.linescan.loss_choice [--motions 10] [--shapes box telescope ...] [--distances 50 100]
                                         [--against bench/out/real_shapes.json] [--stem NAME]

Each case is the real-shapes bench's (``real_shapes.one``: its seeded motion, frames and noise).
At the true motion: the surfels and the last stage's matches as the refinement builds them
(every planar surfel in every other frame, the tightest gate; no thin members), the normalised
residuals ``e = r / sqrt(var)`` and their robust scale ``s``. For each loss ``rho`` the fit's
optimum to first order is one Newton step from the truth,

    dx = H^-1 J^T psi(e / s) s / sqrt(var),    H = J^T diag(rho''(e / s) / var) J,

``psi = rho'``, and its error over the dense bound (``dense_bound.py``) per parameter. Losses:
Cauchy with ``c`` = 2.385 (the fit's, 95 % efficient under Gaussian noise), 4 and 8; Huber with
``c`` = 1.5 and 3; least squares. Beside them the *reweighted* Cauchy step, ``(J^T W J)^-1 J^T W
r`` with the weights ``rho'(e) / e``: it stops short of the optimum (those weights exceed
``rho''``), and is what ``bias_map.py`` measured before 2026-11-29. With ``--against`` (a
``real_shapes`` JSON of the same cases), the whole estimate's errors too: when the Cauchy
column matches them, the whole fit sits at its loss's optimum, and a better search would not
lower its error.

Prints, per shape, the RMS over its cases and the four parameters of error / bound for each
loss, and writes ``bench/out/loss_choice.json`` and a plot of those RMS values.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tumblescan import Motion, Scanner, Scene, random_motion
from tumblescan.linescan.dense.covariance import cauchy_curvature
from tumblescan.linescan.dense.data import DenseData
from tumblescan.linescan.dense.mapping import LineMapping
from tumblescan.linescan.dense.matching import CAUCHY_C, Linearized, cauchyweights, robust_sigma
from tumblescan.linescan.dense.surfels import Surfels
from tumblescan.linescan.simulate import FrameCloud
from tumblescan.linescan.validation import canonical_cov

from ..common import grouped_bars, machine, out_dir, saved_figure, table
from .dense_bound import bound_covariances, bound_sigmas, last_stage_matches, motion_sigmas_deg
from .real_shapes import PARAMETRIC, PARAMS, UNITS, shape_named
from .reuse_diag import at_truth

Loss = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]  # e -> (psi(e), rho''(e))


def cauchy(c: float) -> Loss:
    def loss(e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return e / (1 + (e / c) ** 2), cauchy_curvature(e, c)

    return loss


def huber(c: float) -> Loss:
    def loss(e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.clip(e, -c, c), (np.abs(e) <= c).astype(float)

    return loss


def least_squares(e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return e, np.ones_like(e)


LOSSES: dict[str, Loss] = {
    f"cauchy {CAUCHY_C:g}": cauchy(CAUCHY_C),
    "cauchy 4": cauchy(4.0),
    "cauchy 8": cauchy(8.0),
    "huber 1.5": huber(1.5),
    "huber 3": huber(3.0),
    "least squares": least_squares,
}
REWEIGHTED = f"cauchy {CAUCHY_C:g}, one reweighted step (short of its optimum)"


def normalised(lin: Linearized) -> tuple[np.ndarray, float, np.ndarray]:
    """The residuals over their sigmas ``e``, their robust scale ``s`` and the Jacobian over the sigmas."""
    sd = np.sqrt(lin.var)
    e = lin.r / sd
    return e, max(robust_sigma(e), 1e-12), lin.J / sd[:, None]


def newton_system(e: np.ndarray, s: float, Jn: np.ndarray, loss: Loss) -> tuple[np.ndarray, np.ndarray]:
    """``(H, g)``: ``H = J^T diag(rho''(e / s)) J`` and ``g = J^T psi(e / s) s``, whose solution is
    the optimum of ``loss`` to first order."""
    psi, curvature = loss(e / s)
    return np.asarray(Jn.T @ (Jn * curvature[:, None])), np.asarray(Jn.T @ psi * s)


def newton_step(e: np.ndarray, s: float, Jn: np.ndarray, loss: Loss) -> np.ndarray:
    """The optimum of ``loss`` to first order: ``H^-1 J^T psi(e / s) s`` (:func:`newton_system`)."""
    return np.asarray(np.linalg.solve(*newton_system(e, s, Jn, loss)))


@dataclass(frozen=True)
class TruthCase:
    """One seeded case of the real-shapes bench at its true motion: the motion, scene and
    frames, their dense data and line mapping, the surfels built there, and the dense bound."""

    motion: Motion
    scene: Scene
    sim: FrameCloud
    data: DenseData
    mapping: LineMapping
    surf: Surfels
    bound: dict[str, float]


def truth_case(name: str, distance_m: float, seed: int, size: int) -> TruthCase:
    """``real_shapes.one``'s case (its seeded motion, frames and noise) at the truth."""
    motion = random_motion(np.random.default_rng(seed), distance_m=distance_m)
    scene = Scene(scanner=Scanner(lines=size, pixels=size), shape=shape_named(name))
    sim, data, mapping, surf = at_truth(motion, scene, seed)
    b = bound_covariances(motion, scene, sim, float(sim.t_s.min()))
    return TruthCase(motion, scene, sim, data, mapping, surf, bound_sigmas(b.x, b.facets))


def case(name: str, distance_m: float, seed: int, size: int) -> dict[str, list[float]]:
    """Error / bound per parameter of each loss's Newton step from the truth (and the reweighted one)."""
    tc = truth_case(name, distance_m, seed, size)
    _, lin = last_stage_matches(tc.data, tc.mapping, tc.surf, tc.scene.scanner.noise)
    e, s, Jn = normalised(lin)
    x, bound = tc.mapping.x, tc.bound
    out = {}
    for label, loss in LOSSES.items():
        out[label] = over_bound(x, bound, newton_step(e, s, Jn, loss))
    w = cauchyweights(e, s)
    out[REWEIGHTED] = over_bound(x, bound, np.linalg.solve(Jn.T @ (Jn * w[:, None]), Jn.T @ (w * e)))
    return out


def over_bound(x: np.ndarray, bound: dict[str, float], step_or_cov: np.ndarray) -> list[float]:
    """The spin axis, spin rate, precession axis and precession rate of a step from the truth
    ``x`` (9-vector), or the sigmas of a covariance (9x9), over the dense ``bound``'s."""
    cov = np.outer(step_or_cov, step_or_cov) if step_or_cov.ndim == 1 else step_or_cov
    sig = motion_sigmas_deg(x, canonical_cov(x, cov))
    return [sig[p] / bound[f"{p}_{UNITS[p]}"] for p in PARAMS]


def whole_estimates(path: str) -> dict[tuple[str, float, int], list[float]]:
    """Error / bound per parameter of each case of a ``real_shapes`` JSON."""
    with open(path) as f:
        cases = json.load(f)
    return {
        (c["shape"], float(c["distance_m"]), int(c["seed"])): [
            c["errors"][f"{p}_{UNITS[p]}"] / c["bound"][f"{p}_{UNITS[p]}"] for p in PARAMS
        ]
        for c in cases
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--motions", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--shapes", nargs="+", default=["box", *PARAMETRIC, "hubble"])
    parser.add_argument("--distances", nargs="+", type=float, default=[50.0, 100.0])
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--against", nargs="*", default=[], help="real_shapes JSON files of the same cases")
    parser.add_argument("--stem", default="loss_choice")
    args = parser.parse_args()
    whole: dict[tuple[str, float, int], list[float]] = {}
    for path in args.against:
        whole.update(whole_estimates(path))
    labels = [*LOSSES, REWEIGHTED] + (["whole estimate"] if whole else [])
    print(machine())
    per_shape: dict[str, dict[str, list[list[float]]]] = {}
    for name in args.shapes:
        for distance in args.distances:
            for seed in range(args.first_seed, args.first_seed + args.motions):
                got = case(name, distance, seed, args.size)
                if (name, distance, seed) in whole:
                    got["whole estimate"] = whole[(name, distance, seed)]
                for label, v in got.items():
                    per_shape.setdefault(name, {}).setdefault(label, []).append(v)
            print(f"  {name} at {distance:g} m done", flush=True)
    rms = {
        name: {label: float(np.sqrt(np.mean(np.square(v)))) for label, v in by_label.items()}
        for name, by_label in per_shape.items()
    }
    print("\nRMS over the cases and the four parameters of error / dense bound, per loss's optimum from the truth:")
    print(table([[name, *(f"{r.get(k, np.nan):.2f}" for k in labels)] for name, r in rms.items()], ["shape", *labels]))
    out = out_dir()
    (out / f"{args.stem}.json").write_text(json.dumps({"rms_error_over_bound": rms, "cases": per_shape}, indent=1))
    _plot(rms, labels, out / f"{args.stem}.png")
    print(f"wrote {out / args.stem}.json and .png")


def _plot(rms: dict[str, dict[str, float]], labels: list[str], path: Path) -> None:
    shapes = list(rms)
    series = {label: [rms[s].get(label, np.nan) for s in shapes] for label in labels}
    title = "Each loss's optimum from the truth (lower is better; 1 = efficient)"
    with saved_figure(path, title=title, ylabel="RMS error / dense bound", size=(10, 4.5), legend_columns=2) as ax:
        grouped_bars(ax, shapes, series, hatched=REWEIGHTED)
        ax.axhline(1.0, color="k", lw=0.8, ls=":")


if __name__ == "__main__":
    main()
