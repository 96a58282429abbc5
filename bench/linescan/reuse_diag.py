"""How much the pairwise residuals lose by using each surfel's centroid noise in many pairs.

    python -m bench.linescan.reuse_diag [--shapes telescope dish-boom] [--seeds 1] [--distances 50]

At the true motion: surfels and the last stage's matches (every other frame, tightest gate) as
the refinement builds them. For several residual designs on the same surfels, the linearized
estimator ``dx = A^-1 J^T W r`` (``W = 1/var``) and its exact covariance when the only noise is
each surfel anchor's own, independent between surfels (variance ``v/N`` along the normal),
however many residuals it enters: ``A^-1 (sum_j d_j M_j M_j^T + tilt) A^-1`` with ``M_j`` the
weighted Jacobian rows summed with the sign and coefficient of surfel ``j`` in each residual.
Printed over the bound of every hit and of the hits in planar surfels, beside the covariance the
design claims (``A^-1``, residuals independent) and the one-step error from the truth.

Designs: ``pair`` (today's: ``n . (a_s - a_t)``, variance ``v_s/N_s + v_t/N_t + tilt``);
``pair/k`` (each pair's variance inflated by ``W_s / (w_s + w_t)``, ``W_s`` the summed
precision ``N/v`` of the source and all its targets: on a complete cluster this gives each pair
the weight ``w_s w_t / W`` of the pooled plane with its offset eliminated); ``pooled`` (one
residual per source surfel, against the precision-weighted mean of its targets' planes).
"""

from __future__ import annotations

import argparse

import numpy as np

from tumblescan import Motion, Scanner, Scene, random_motion
from tumblescan.linescan.dense.covariance import cauchy_curvature, patches, sandwich
from tumblescan.linescan.dense.data import DenseData
from tumblescan.linescan.dense.mapping import LineMapping
from tumblescan.linescan.dense.matching import CAUCHY_C, cauchyweights, robust_sigma
from tumblescan.linescan.dense.surfels import Surfels, build_surfels
from tumblescan.linescan.sensor import SensorNoise
from tumblescan.linescan.simulate import FrameCloud
from tumblescan.linescan.validation import canonical_cov

from ..common import table
from .dense_bound import dense_bound, face_of_hits, last_stage_matches, motion_sigmas_deg
from .real_shapes import shape_named
from .truth import frames_at_truth

PARAMS = ("spin_axis", "spin_rate", "precession_axis", "precession_rate")
UNIT = ("deg", "deg_s", "deg", "deg_s")


def analyse(
    J: np.ndarray,
    var: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    coef: np.ndarray,
    d: np.ndarray,
    indep: np.ndarray,
    r: np.ndarray,
    m: int,
) -> dict[str, np.ndarray]:
    """Covariances and one-step errors of one design (9x9 each, or 9-vectors).

    rows/cols/coef: residual ``rows[k]`` holds ``coef[k]`` times surfel ``cols[k]``'s anchor noise
    (variance ``d``); ``indep``: each residual's own independent variance (the normals' tilt).
    ``claimed``: ``s^2 A^-1`` (residuals independent); ``true``: under the surfels' noise alone;
    ``step``: least squares from the truth; ``robust``: the Cauchy cost's Newton step from the truth
    (where the fit converges, to first order)."""
    w = 1.0 / var
    A = J.T @ (J * w[:, None])
    Ainv = np.linalg.inv(A)
    wJ = J * w[:, None]
    M = np.zeros((m, J.shape[1]))
    np.add.at(M, cols, wJ[rows] * coef[:, None])
    B = M.T @ (M * d[:, None]) + (wJ * indep[:, None]).T @ wJ
    e = r / np.sqrt(var)
    s = robust_sigma(e)
    wr = cauchyweights(e, s) * w
    # The cost's Hessian, not the reweighted steps' matrix: the fit converges to its optimum.
    Ar = J.T @ (J * (cauchy_curvature(e, CAUCHY_C * s) * w)[:, None])
    return {
        "claimed": s**2 * Ainv,
        "true": Ainv @ B @ Ainv,
        "step": Ainv @ (wJ.T @ r),
        "robust": np.linalg.solve(Ar, J.T @ (wr * r)),
        "scale": np.array(s),
    }


def designs(
    data: DenseData, surf: Surfels, mapping: LineMapping, noise: SensorNoise
) -> tuple[dict[str, dict[str, np.ndarray]], str]:
    """Every design's :func:`analyse` on the last stage's matches at ``mapping``, and a summary line."""
    cells = np.flatnonzero(surf.planar)
    mt, lin = last_stage_matches(data, mapping, surf, noise)
    m = len(surf.count)
    n = len(lin.r)
    d = surf.var_m2 / np.maximum(surf.count, 1)
    tilt = lin.var - d[mt.src] - d[mt.dst]
    idx = np.arange(n)
    rows = np.concatenate([idx, idx])
    cols = np.concatenate([mt.src, mt.dst])
    coef = np.concatenate([np.ones(n), -np.ones(n)])
    out = {}
    out["pair"] = analyse(lin.J, lin.var, rows, cols, coef, d, tilt, lin.r, m)
    # Cluster weights: W_s = w_s + the summed precisions of the source's targets.
    wsurf = 1.0 / d
    W = wsurf.copy()
    np.add.at(W, mt.src, wsurf[mt.dst])
    infl = W[mt.src] / (wsurf[mt.src] + wsurf[mt.dst])
    out["pair/k"] = analyse(lin.J, lin.var * infl, rows, cols, coef, d, tilt * infl, lin.r, m)
    # Usage count inflation: each surfel's noise in k residuals.
    uses = np.bincount(np.concatenate([mt.src, mt.dst]), minlength=m).astype(float)
    infl_u = (d[mt.src] * uses[mt.src] + d[mt.dst] * uses[mt.dst] + tilt) / lin.var
    out["pair*uses"] = analyse(lin.J, lin.var * infl_u, rows, cols, coef, d, tilt * infl_u, lin.r, m)
    # Pooled: one residual per source, the precision-weighted mean of its pair residuals.
    u = 1.0 / (d[mt.dst] + tilt)
    srcs, inv = np.unique(mt.src, return_inverse=True)
    U = np.bincount(inv, u)
    k = len(srcs)
    r_p = np.bincount(inv, u * lin.r) / U
    J_p = np.stack([np.bincount(inv, u * lin.J[:, j]) for j in range(lin.J.shape[1])], axis=1) / U[:, None]
    var_p = d[srcs] + 1.0 / U
    rows_p = np.concatenate([np.arange(k), inv])
    cols_p = np.concatenate([srcs, mt.dst])
    coef_p = np.concatenate([np.ones(k), -u / U[inv]])
    tilt_p = np.bincount(inv, (u / U[inv]) ** 2 * tilt)
    out["pooled"] = analyse(J_p, var_p, rows_p, cols_p, coef_p, d, tilt_p, r_p, m)
    # The refinement's own covariance (patch jackknife) at these matches.
    e = lin.r / np.sqrt(lin.var)
    scale = max(robust_sigma(e), 1e-12)
    cluster = patches(mapping.apply(surf.anchor_obs[mt.src], surf.line[mt.src]), data.extent_m / 10)
    out["pair"]["jackknife"] = sandwich(lin.J, lin.r, lin.var, CAUCHY_C * scale, cluster, None)
    line = (f"residuals {n}, sources {k}, uses per surfel median {np.median(uses[uses > 0]):.0f}, "
            f"d median {1e6 * np.median(d[cells]):.2f} mm^2, d p90/p10 "
            f"{np.percentile(d[cells], 90) / np.percentile(d[cells], 10):.1f}")  # fmt: skip
    return out, line


def at_truth(motion: Motion, scene: Scene, noise_seed: int) -> tuple[FrameCloud, DenseData, LineMapping, Surfels]:
    """:func:`truth.frames_at_truth` and the surfels built at the true motion as the estimator builds them."""
    sim, data, mapping = frames_at_truth(motion, scene, noise_seed)
    return sim, data, mapping, build_surfels(data, mapping, scene.scanner.noise)


def case(name: str, distance_m: float, seed: int, size: int, draws: int) -> None:
    """Motion ``seed``; noise draws ``seed, seed + 1000, ...``; the bound of the first draw."""
    motion = random_motion(np.random.default_rng(seed), distance_m=distance_m)
    scene = Scene(scanner=Scanner(lines=size, pixels=size), shape=shape_named(name))
    noise = scene.scanner.noise
    sq: dict[tuple[str, str], list[dict[str, float]]] = {}
    for draw in range(draws):
        sim, data, mapping, surf = at_truth(motion, scene, seed + 1000 * draw)
        T, x_true = float(sim.t_s.min()), mapping.x
        if draw == 0:
            kept = np.ones(len(sim.xyz_m), dtype=bool) if data.kept is None else data.kept
            used = np.zeros(len(sim.xyz_m), dtype=bool)
            used[kept] = surf.planar[surf.point_cell]
            faces = face_of_hits(scene, motion, sim.reference_m)
            b_all = dense_bound(motion, scene, sim, T, faces=faces)
            b_used = dense_bound(motion, scene, sim, T, hits=used, faces=faces)
        out, line = designs(data, surf, mapping, noise)
        if draw == 0:
            print(f"\n{name} {distance_m:g} m motion {seed}, {draws} noise draws: {line}")
        for key, res in out.items():
            for kind, val in res.items():
                if kind == "scale":
                    continue
                cov = np.outer(val, val) if val.ndim == 1 else val
                sq.setdefault((key, kind), []).append(motion_sigmas_deg(x_true, canonical_cov(x_true, cov)))
    rows_t = []
    for key in ("pair", "pair/k", "pair*uses", "pooled"):
        for p, un in zip(PARAMS, UNIT, strict=True):
            b, bu = b_all[f"{p}_{un}"], b_used[f"{p}_{un}"]

            def rms(kind: str, _p: str = p, _k: str = key) -> float:
                return float(np.sqrt(np.mean([v[_p] ** 2 for v in sq[(_k, kind)]])))

            jk = f"{rms('jackknife') / b:.2f}" if (key, "jackknife") in sq else "-"
            true, claimed = rms("true"), rms("claimed")
            rows_t.append([key, p, f"{bu / b:.2f}", f"{claimed / b:.2f}", f"{true / b:.2f}", f"{true / bu:.2f}", jk,
                           f"{rms('step') / b:.2f}", f"{rms('robust') / b:.2f}"])  # fmt: skip
    print(table(rows_t, ["design", "param", "bound-used/bound", "claimed/bound", "true/bound", "true/bound-used",
                         "jackknife/bound", "LS step err/bound", "robust step err/bound"]))  # fmt: skip
    print("(errors: RMS over the draws of one step from the truth; sigmas: RMS over the draws)", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--shapes", nargs="+", default=["telescope", "dish-boom"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[1])
    parser.add_argument("--distances", nargs="+", type=float, default=[50.0])
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--draws", type=int, default=1, help="noise draws of each motion")
    args = parser.parse_args()
    for name in args.shapes:
        for dist in args.distances:
            for s in args.seeds:
                case(name, dist, s, args.size, args.draws)


if __name__ == "__main__":
    main()
