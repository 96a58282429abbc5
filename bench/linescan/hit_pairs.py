"""The hits the surfels leave out, each matched to the nearest planar surfel of a partner frame.

    python -m bench.linescan.hit_pairs [--motions 5] [--shapes box long-array] [--distances 50 100]
                                       [--oracle] [--no-handover] [--stem NAME] [--report A.json B.json]

Measured at the true motion, as ``loss_choice.py`` measures the fit's loss: the fit's surfel
pairs (the last stage's matches built at the truth) and, beside them, the hits outside every
planar surfel. Each such hit ``x`` of frame ``f`` is matched, in every other frame ``b``, to
the nearest planar surfel ``a_t`` of ``b`` (within one surfel size at ``T``) and kept when

    r = n_t . (M(x) - a_t),   |r| <= 3 sqrt(var_x + v_t / N_t),   in-plane offset <= 0.75 surfel

with ``var_x`` the hit's sensor variance along ``n_t`` and the plane facing the hit's sensor.
The hits of one cell matched to one target are one residual: their mean ``r`` and ``J``, and

    var = mean(var_x) / k + v_t / N_t + mean(offset^2) v_nt

(the target's noise enters once per group, as a pair's does). Designs, each the Cauchy cost's
optimum to first order from the truth (one Newton step, each block at its own robust scale):
the pairs, the pairs with the groups, the groups alone, and the groups by generalised least
squares with each target's anchor noise a random effect shared by its groups, alone and beside
the pairs; with their own sigmas (the residuals taken as independent). ``--oracle``: also only
the groups whose hits lie on their target's face of the mesh. ``--no-handover``: the surfels
built without handing points across edges (``faces.assign_to_faces``).

Prints per shape the RMS over the cases and the four parameters of error / dense bound, and its
difference from the pairs' as a 90 % bootstrap interval over the cases; writes a JSON and a plot.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from tumblescan import Scanner, Scene, random_motion
from tumblescan.linescan.dense import surfels
from tumblescan.linescan.dense.covariance import cauchy_curvature
from tumblescan.linescan.dense.data import DenseData
from tumblescan.linescan.dense.mapping import LineMapping
from tumblescan.linescan.dense.matching import CAUCHY_C, Linearized, robust_sigma
from tumblescan.linescan.dense.surfels import Surfels, normal_variance
from tumblescan.linescan.sensor import SensorNoise
from tumblescan.linescan.validation import canonical_cov

from ..common import machine, out_dir, table
from .dense_bound import bound_covariances, bound_sigmas, face_of_hits, last_stage_matches, motion_sigmas_deg
from .real_shapes import PARAMS, UNITS, shape_named
from .reuse_diag import at_truth

MAX_INPLANE = 0.75  # surfel sizes
GATE_SIGMAS = 3.0


def hit_groups(
    data: DenseData,
    mapping: LineMapping,
    surf: Surfels,
    noise: SensorNoise,
    *,
    faces: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[HitGroups, float]:
    """The left-out hits' groups (see the module) and the share of all hits they use."""
    h_all = np.flatnonzero(~surf.planar[surf.point_cell])
    x_ref = mapping.apply(data.xyz_m[h_all], data.line[h_all])
    sensor_ref = mapping.apply(np.zeros((len(h_all), 3)), data.line[h_all])
    anchor_ref = mapping.apply(surf.anchor_obs, surf.line)
    normal_ref = mapping.rotate(surf.normal_obs, surf.line)
    m = len(surf.planar)
    rs, Js, vs, ts = [], [], [], []
    used = np.zeros(len(h_all), dtype=bool)
    for b in range(data.n_frames):
        targets = np.flatnonzero((data.cell_frame == b) & surf.planar)
        sel = np.flatnonzero(data.frame[h_all] != b)
        if len(targets) == 0 or len(sel) == 0:
            continue
        dist, nn = cKDTree(anchor_ref[targets]).query(x_ref[sel], k=1, distance_upper_bound=data.surfel_m)
        ok = np.isfinite(dist)
        sel, t = sel[ok], targets[nn[ok]]
        n = normal_ref[t]
        d = x_ref[sel] - anchor_ref[t]
        r = np.einsum("ni,ni->n", n, d)
        off2 = np.einsum("ni,ni->n", d, d) - r**2
        h = h_all[sel]
        n_obs = np.einsum("nji,nj->ni", mapping.Rt[data.line[h]], n)
        var_x = normal_variance(noise, data.xyz_m[h], n_obs)
        var_t = surf.var_m2[t] / surf.count[t]
        facing = np.einsum("ni,ni->n", n, sensor_ref[sel] - x_ref[sel]) > 0
        keep = facing & (off2 <= (MAX_INPLANE * data.surfel_m) ** 2) & (r**2 <= GATE_SIGMAS**2 * (var_x + var_t))
        if faces is not None:
            keep &= faces[0][h] == faces[1][t]
        sel, t, n, r, off2, h, var_x = sel[keep], t[keep], n[keep], r[keep], off2[keep], h[keep], var_x[keep]
        if len(sel) == 0:
            continue
        used[sel] = True
        J = mapping.normal_derivative(n, data.xyz_m[h], data.line[h]) - mapping.normal_derivative(
            n, surf.anchor_obs[t], surf.line[t]
        )
        _, group, k = np.unique(data.cell[h] * m + t, return_inverse=True, return_counts=True)
        g = len(k)

        def mean(v: np.ndarray, group: np.ndarray = group, k: np.ndarray = k, g: int = g) -> np.ndarray:
            return np.bincount(group, v, minlength=g) / k

        t_g = np.zeros(g, dtype=np.int64)
        t_g[group] = t
        rs.append(mean(r))
        Js.append(np.stack([mean(J[:, j]) for j in range(J.shape[1])], axis=1))
        vs.append(mean(var_x) / k + surf.var_m2[t_g] / surf.count[t_g] + mean(off2) * surf.normal_var_rad2[t_g])
        ts.append(t_g)
    lin = Linearized(np.concatenate(rs), np.concatenate(Js), np.concatenate(vs))
    target = np.concatenate(ts)
    return HitGroups(lin, target, surf.var_m2[target] / surf.count[target]), float(used.sum()) / len(data.xyz_m)


@dataclass(frozen=True)
class HitGroups:
    """The groups' residuals (``lin``, the variance with the target's share in it), each group's
    target surfel and that target's anchor variance along its normal (m^2), which every group
    matched to it shares."""

    lin: Linearized
    target: np.ndarray
    shared_var: np.ndarray


def random_effect_system(groups: HitGroups) -> tuple[np.ndarray, np.ndarray]:
    """Normal equations ``(H, g)`` of the groups by generalised least squares, each target's
    anchor noise a random effect shared by its groups: per target, with ``w = 1 / v`` (``v`` a
    group's own variance, the target's share taken out) and ``tau`` the target's,

        H = sum w J J^T - (sum w J)(sum w J)^T / (1 / tau + sum w),   g likewise with ``r``."""
    lin = groups.lin
    w = 1.0 / (lin.var - groups.shared_var)
    _, c = np.unique(groups.target, return_inverse=True)
    k = int(c.max()) + 1
    tau = np.zeros(k)
    tau[c] = groups.shared_var
    sw = np.bincount(c, w, minlength=k)
    sJ = np.stack([np.bincount(c, w * lin.J[:, j], minlength=k) for j in range(lin.J.shape[1])], axis=1)
    sr = np.bincount(c, w * lin.r, minlength=k)
    shrink = 1.0 / (1.0 / tau + sw)
    H = lin.J.T @ (lin.J * w[:, None]) - sJ.T @ (sJ * shrink[:, None])
    g = lin.J.T @ (w * lin.r) - sJ.T @ (sr * shrink)
    return np.asarray(H), np.asarray(g)


def cauchy_system(blocks: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """The Cauchy cost's Newton system ``(H, g)`` at the truth over the stacked scaled blocks
    ``(z, Jz)`` (:func:`scaled`): the step is ``H^-1 g``."""
    z = np.concatenate([b[0] for b in blocks])
    Jz = np.concatenate([b[1] for b in blocks])
    psi = z / (1 + (z / CAUCHY_C) ** 2)
    return np.asarray(Jz.T @ (Jz * cauchy_curvature(z, CAUCHY_C)[:, None])), np.asarray(Jz.T @ psi)


def majority_face(point_cell: np.ndarray, hit_face: np.ndarray, m: int) -> np.ndarray:
    """Each surfel's most common face among its points (``-2`` for none)."""
    nf = int(hit_face.max()) + 2
    keys, counts = np.unique(point_cell * nf + hit_face + 1, return_counts=True)
    cell, face = np.divmod(keys, nf)
    order = np.lexsort((counts, cell))
    out = np.full(m, -2, dtype=np.int64)
    out[cell[order]] = face[order] - 1  # the last write per cell is its largest count
    return out


def scaled(lin: Linearized) -> tuple[np.ndarray, np.ndarray]:
    """Residuals and Jacobian over their sigmas and the block's robust scale."""
    sd = np.sqrt(lin.var)
    e = lin.r / sd
    s = max(robust_sigma(e), 1e-12)
    return e / s, lin.J / (sd * s)[:, None]


def cauchy_step(blocks: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """One Newton step of the Cauchy cost from the truth over the stacked blocks ``(z, Jz)``."""
    H, g = cauchy_system(blocks)
    return np.asarray(np.linalg.solve(H, g))


def cauchy_cov(blocks: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """The sandwich covariance of that step, its residuals taken as independent."""
    z = np.concatenate([b[0] for b in blocks])
    Jz = np.concatenate([b[1] for b in blocks])
    psi = z / (1 + (z / CAUCHY_C) ** 2)
    Hi = np.linalg.inv(Jz.T @ (Jz * cauchy_curvature(z, CAUCHY_C)[:, None]))
    return np.asarray(Hi @ (Jz.T @ (Jz * psi[:, None] ** 2)) @ Hi)


def case(
    name: str, distance_m: float, seed: int, size: int, *, oracle: bool
) -> tuple[dict[str, list[float]], float, float]:
    motion = random_motion(np.random.default_rng(seed), distance_m=distance_m)
    scene = Scene(scanner=Scanner(lines=size, pixels=size), shape=shape_named(name))
    noise = scene.scanner.noise
    sim, data, mapping, surf = at_truth(motion, scene, seed)
    T = float(sim.t_s.min())
    bound = bound_sigmas(*(lambda b: (b.x, b.facets))(bound_covariances(motion, scene, sim, T)))
    _, pairs = last_stage_matches(data, mapping, surf, noise)
    hg, share = hit_groups(data, mapping, surf, noise)
    groups = hg.lin
    x = mapping.x

    def over_bound(dx: np.ndarray) -> list[float]:
        cov = np.outer(dx, dx) if dx.ndim == 1 else dx
        sig = motion_sigmas_deg(x, canonical_cov(x, cov))
        return [sig[p] / bound[f"{p}_{UNITS[p]}"] for p in PARAMS]

    p = scaled(pairs)
    out = {
        "surfel pairs": over_bound(cauchy_step([p])),
        "pairs + hit groups": over_bound(cauchy_step([p, scaled(groups)])),
        "hit groups alone": over_bound(cauchy_step([scaled(groups)])),
        "sigma: pairs": over_bound(cauchy_cov([p])),
        "sigma: pairs + hit groups": over_bound(cauchy_cov([p, scaled(groups)])),
        "sigma: hit groups alone": over_bound(cauchy_cov([scaled(groups)])),
    }
    # The groups by generalised least squares, the targets' noise shared (no robust loss: the
    # gate has kept them within 3 sigmas), alone and beside the pairs' Cauchy system.
    Hg, gg = random_effect_system(hg)
    out["hit groups alone, shared targets"] = over_bound(np.linalg.solve(Hg, gg))
    out["sigma: hit groups alone, shared targets"] = over_bound(np.linalg.inv(Hg))
    # Each block weighed by its own robust scale, as the pairs' rows are (scaled()).
    s_g2 = max(robust_sigma(groups.r / np.sqrt(groups.var)), 1e-12) ** 2
    Hp, gp = cauchy_system([p])
    out["pairs + hit groups, shared targets"] = over_bound(np.linalg.solve(Hp + Hg / s_g2, gp + gg / s_g2))
    if oracle:
        # Only the groups whose hits lie on their target's face of the mesh (most of its points').
        hit_face = face_of_hits(scene, motion, sim.reference_m)[0]
        if data.kept is not None:
            hit_face = hit_face[data.kept]
        faces = (hit_face, majority_face(surf.point_cell, hit_face, len(surf.planar)))
        same = scaled(hit_groups(data, mapping, surf, noise, faces=faces)[0].lin)
        out["pairs + hit groups on the target's face"] = over_bound(cauchy_step([p, same]))
        out["hit groups on the target's face alone"] = over_bound(cauchy_step([same]))
    planar_share = float(np.mean(surf.planar[surf.point_cell]))
    return out, planar_share, share


def paired_interval(
    design: np.ndarray, base: np.ndarray, rng: np.random.Generator, n_boot: int = 2000
) -> tuple[float, float]:
    """90 % bootstrap interval, resampling the cases, of ``RMS(design) - RMS(base)``; each
    argument is ``(cases, 4)`` error / bound. A case's four parameters move together (the
    rotation's parameters are correlated), so the case, not the parameter, is the unit."""
    k = len(design)
    idx = rng.integers(0, k, (n_boot, k))
    diff = np.sqrt(np.mean(design[idx] ** 2, axis=(1, 2))) - np.sqrt(np.mean(base[idx] ** 2, axis=(1, 2)))
    lo, hi = np.quantile(diff, [0.05, 0.95])
    return float(lo), float(hi)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--motions", type=int, default=5)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--shapes", nargs="+", default=["box", "long-array"])
    parser.add_argument("--distances", nargs="+", type=float, default=[50.0, 100.0])
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--stem", default="hit_pairs")
    parser.add_argument("--oracle", action="store_true", help="also the groups on their target's face of the mesh")
    parser.add_argument(
        "--no-handover", action="store_true", help="the surfels built without handing points across edges"
    )
    parser.add_argument("--report", nargs="*", default=[], help="merge these JSON files instead of running")
    args = parser.parse_args()
    if args.no_handover:
        # Every point stays in its own cell (the build's assign_to_faces, switched off here only).
        surfels.assign_to_faces = lambda planes, candidate, face: planes.cell.copy()
    print(machine())
    per: dict[str, dict[str, list[list[float]]]] = {}
    shares: dict[str, list[list[float]]] = {}
    for path in args.report:
        got = json.loads(Path(path).read_text())
        for name, by in got["cases"].items():
            for k, v in by.items():
                per.setdefault(name, {}).setdefault(k, []).extend(v)
            shares.setdefault(name, []).extend(got["shares"][name])
    for name in [] if args.report else args.shapes:
        for distance in args.distances:
            for seed in range(args.first_seed, args.first_seed + args.motions):
                got, planar, share = case(name, distance, seed, args.size, oracle=args.oracle)
                shares.setdefault(name, []).append([planar, share])
                for k, v in got.items():
                    per.setdefault(name, {}).setdefault(k, []).append(v)
                print(f"  {name} {distance:g} m seed {seed} done", flush=True)
    rng = np.random.default_rng(0)
    rows = []
    for name, by in per.items():
        sh = np.mean(shares[name], axis=0)
        base = np.asarray(by["surfel pairs"])
        for k, v in by.items():
            a = np.asarray(v)
            lo, hi = (np.nan, np.nan) if k.startswith("sigma") or k == "surfel pairs" else paired_interval(a, base, rng)
            rows.append(
                [
                    name,
                    k,
                    str(len(a)),
                    f"{np.sqrt(np.mean(a**2)):.2f}",
                    f"{lo:+.2f} .. {hi:+.2f}",
                    f"{100 * sh[0]:.1f} + {100 * sh[1]:.1f} %",
                ]
            )
    print("\nRMS over the cases and the four parameters of error / dense bound at each design's optimum from the truth")
    print(
        "('sigma': the design's own, its residuals taken as independent); the pairs' difference, 90 % over the cases:"
    )
    print(table(rows, ["shape", "design", "cases", "RMS / bound", "minus pairs", "hits: surfels + groups"]))
    out = out_dir()
    (out / f"{args.stem}.json").write_text(json.dumps({"cases": per, "shares": shares}, indent=1))
    _plot(per, out / f"{args.stem}.png")
    print(f"wrote {out / args.stem}.json and .png")


def _plot(per: dict[str, dict[str, list[list[float]]]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = [k for k in next(iter(per.values())) if not k.startswith("sigma")]
    fig, ax = plt.subplots(figsize=(9, 4.5))
    width = 0.8 / len(labels)
    shapes = list(per)
    for i, label in enumerate(labels):
        rms = [np.sqrt(np.mean(np.square(per[s][label]))) for s in shapes]
        ax.bar(np.arange(len(shapes)) + (i - (len(labels) - 1) / 2) * width, rms, width, label=label)
    ax.axhline(1.0, color="k", lw=0.8, ls=":")
    ax.set_xticks(np.arange(len(shapes)), shapes)
    ax.set_ylabel("RMS error / dense bound")
    ax.set_title("The left-out hits matched to partner surfels, at the truth (lower is better)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
