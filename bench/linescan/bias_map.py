"""Where a bias of the dense fit comes from: the step from the truth, per patch of the target.

    python -m bench.linescan.bias_map [--shape hubble] [--distance 50] [--seed 2] [--draws 6] [--top 8]

At the true motion, for several noise draws of one motion (noise seeds ``seed + 1000 k``): the
surfels and the last stage's matches as the refinement builds them, and one Cauchy-weighted
Gauss-Newton step from the truth, ``dx = A^-1 J^T W r`` (``W`` the Cauchy weights at unit scale
over the residuals' variances). Its mean over the draws is the fit's bias to first order; its
RMS, the bias and the noise together. Each patch of the target (the covariance's clusters:
cubes of a tenth of the extent) contributes ``A^-1 J_p^T W_p r_p``; a patch whose contribution
keeps its sign in every draw (mean about as large as the mean of its magnitudes) is a bias of
that part of the surface. Sizes are in units of the dense bound (``dense_bound.py``), per
parameter (spin axis, spin rate, precession axis, precession rate).

Noise-free frames do not serve: the normals are taken from the scatter less the sensor noise's
covariance (``surfels._noise_free_normals``), which a noise-free cell does not have; on the box
that alone makes a step of 2.2 bounds.
"""

from __future__ import annotations

import argparse

import numpy as np

from tumblescan import Scanner, Scene, random_motion
from tumblescan.linescan.dense.covariance import patches
from tumblescan.linescan.dense.matching import cauchyweights
from tumblescan.linescan.validation import canonical_cov

from ..common import table
from .dense_bound import dense_bound, last_stage_matches, motion_sigmas_deg
from .real_shapes import PARAMS, UNITS, shape_named
from .reuse_diag import at_truth


def in_bounds(x: np.ndarray, delta: np.ndarray, bound: dict[str, float]) -> np.ndarray:
    """``|delta|`` in each of the four parameters over its bound (deg, deg/s alike)."""
    s = motion_sigmas_deg(x, canonical_cov(x, np.outer(delta, delta)))
    return np.array([s[p] / bound[f"{p}_{UNITS[p]}"] for p in PARAMS])


Patches = dict[tuple[int, ...], tuple[np.ndarray, int, float, np.ndarray]]


def steps(
    name: str, distance_m: float, seed: int, draws: int
) -> tuple[np.ndarray, list[Patches], np.ndarray, dict[str, float]]:
    """Per draw: the whole step ``(9,)`` and each patch's ``(contribution, residuals, mean e,
    centre at T)``, keyed by the patch's cube; the truth and the bound."""
    motion = random_motion(np.random.default_rng(seed), distance_m=distance_m)
    scene = Scene(scanner=Scanner(lines=512, pixels=512), shape=shape_named(name))
    totals, per_patch = [], []
    for draw in range(draws):
        sim, data, mapping, surf = at_truth(motion, scene, seed + 1000 * draw)
        if draw == 0:
            bound = dense_bound(motion, scene, sim, float(sim.t_s.min()))
        mt, lin = last_stage_matches(data, mapping, surf, scene.scanner.noise)
        e = lin.r / np.sqrt(lin.var)
        w = cauchyweights(e, 1.0) / lin.var
        Ainv = np.linalg.inv(lin.J.T @ (lin.J * w[:, None]))
        totals.append(Ainv @ (lin.J.T @ (w * lin.r)))
        anchor_T = mapping.apply(surf.anchor_obs[mt.src], surf.line[mt.src])
        cube = data.extent_m / 10
        cluster = patches(anchor_T, cube)
        found: Patches = {}
        for k in range(int(cluster.max()) + 1):
            m = cluster == k
            centre = anchor_T[m].mean(axis=0)
            key = tuple(int(v) for v in np.floor(centre / cube))
            found[key] = (Ainv @ (lin.J[m].T @ (w[m] * lin.r[m])), int(m.sum()), float(e[m].mean()), centre)
        per_patch.append(found)
    return np.array(totals), per_patch, mapping.x, bound


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--shape", default="hubble")
    parser.add_argument("--distance", type=float, default=50.0)
    parser.add_argument("--seed", type=int, default=2)
    parser.add_argument("--draws", type=int, default=6)
    parser.add_argument("--top", type=int, default=8)
    args = parser.parse_args()
    totals, per_patch, x, bound = steps(args.shape, args.distance, args.seed, args.draws)
    print(f"{args.shape} {args.distance:g} m seed {args.seed}, {args.draws} noise draws; step from the truth / bound")
    mean = in_bounds(x, totals.mean(axis=0), bound)
    rms = np.sqrt(np.mean([in_bounds(x, t, bound) ** 2 for t in totals], axis=0))
    print(table([["mean (bias)", *(f"{v:.2f}" for v in mean)], ["RMS", *(f"{v:.2f}" for v in rms)]],
                ["", *PARAMS]))  # fmt: skip
    rows = []
    for key in set().union(*per_patch):
        parts = [d[key] for d in per_patch if key in d]
        contrib = [p[0] for p in parts]
        steady = in_bounds(x, np.sum(contrib, axis=0) / len(per_patch), bound)
        magnitude = np.mean([in_bounds(x, c, bound).max() for c in contrib])
        n, e_mean, centre = parts[0][1], np.mean([p[2] for p in parts]), parts[0][3]
        rows.append([steady.max(), *(f"{v:.2f}" for v in steady), f"{magnitude:.2f}", n, f"{e_mean:+.3f}",
                     np.array2string(np.round(centre, 2))])  # fmt: skip
    rows.sort(key=lambda r: -float(r[0]))
    print(f"\nthe {args.top} patches with the largest mean contribution (/ bound), the mean of its magnitude per draw")
    print(table([r[1:] for r in rows[: args.top]], [*PARAMS, "per draw", "residuals", "mean e", "centre at T (m)"]))


if __name__ == "__main__":
    main()
