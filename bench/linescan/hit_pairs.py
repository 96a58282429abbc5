"""The hits the surfels leave out, each matched to the nearest planar surfel of a partner frame.

    python -m bench.linescan.hit_pairs [--motions 5] [--shapes box long-array] [--distances 50 100]
                                       [--oracle] [--no-handover] [--grazing COS] [--stem NAME]
    python -m bench.linescan.hit_pairs --report A.json B.json [--baseline C.json D.json]

Measured at the true motion, as ``loss_choice.py`` measures the fit's loss: the fit's surfel
pairs (the last stage's matches built at the truth) and, beside them, the hits outside every
planar surfel. Each such hit ``x`` of frame ``f`` is matched, in every other frame ``b``, to
the nearest planar surfel ``a_t`` of ``b`` (within one surfel size at ``T``) and kept when

    r = n_t . (M(x) - a_t),   |r| <= 3 sqrt(var_x + v_t / N_t),   in-plane offset <= 0.75 surfel

with ``var_x`` the hit's sensor variance along ``n_t`` and the plane facing the hit's sensor
(with ``--grazing COS``, also seen at grazing incidence: ``|n_t . u| < COS``, ``u`` the sight;
the fit's ``dense.grazing`` takes these, with ``COS`` = 0.3, off its thin members' hits).
The hits of one cell matched to one target are one residual: their mean ``r`` and ``J``, and

    var = mean(var_x) / k + v_t / N_t + |mean in-plane offset|^2 v_nt

(the target's anchor and tilt enter once per group, as a pair's do). Designs, each the Cauchy
cost's optimum to first order from the truth (one Newton step, each block at its own robust
scale): the pairs, the pairs with the groups, the groups alone; and their sigmas, the sandwich
clustered by source cell (a hit is in up to one group per partner frame; a pair's source surfel
in one pair per partner frame). ``--oracle``: also only the groups whose hits lie on their
target's face of the mesh. ``--no-handover``: the surfels built without handing points across
edges (``handover.assign_to_faces``).

Prints per shape the RMS over the cases and the four parameters of error / dense bound, and its
difference from the pairs' as a 90 % bootstrap interval over the cases (or, with ``--baseline``,
from the same design in other runs of the same cases, paired by case); writes a JSON and a plot.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass
from pathlib import Path
from typing import TypedDict

import numpy as np

from tumblescan.linescan.dense import surfels
from tumblescan.linescan.dense.covariance import sandwich
from tumblescan.linescan.dense.data import DenseData
from tumblescan.linescan.dense.grazing import match_to_surfels
from tumblescan.linescan.dense.mapping import LineMapping
from tumblescan.linescan.dense.matching import CAUCHY_C, Linearized
from tumblescan.linescan.dense.surfels import Surfels, normal_variance
from tumblescan.linescan.sensor import SensorNoise

from ..common import grouped_bars, machine, out_dir, saved_figure, table
from .dense_bound import face_of_hits, last_stage_matches, majority_face
from .loss_choice import cauchy, newton_system, normalised, over_bound, truth_case


@dataclass(frozen=True)
class HitMatches:
    """Each matched hit ``(k,)``: the hit, its target surfel and its group (one per source cell
    and target, ``0 .. groups - 1``); and each group's source cell ``(groups,)``."""

    hit: np.ndarray
    target: np.ndarray
    group: np.ndarray
    cell: np.ndarray


def match_hits(
    data: DenseData,
    mapping: LineMapping,
    surf: Surfels,
    noise: SensorNoise,
    *,
    faces: tuple[np.ndarray, np.ndarray] | None = None,
    max_cos: float | None = None,
) -> tuple[HitMatches, float]:
    """The left-out hits matched to partner frames' planar surfels (see the module), and the
    share of all hits matched. faces: each hit's face of the mesh and each surfel's majority
    face; only hits on their target's face are matched (an oracle). max_cos: only hits whose
    sight meets the target's plane with ``|cos(incidence)|`` below it (grazing hits)."""
    hit, target = match_to_surfels(
        data, mapping, surf, noise, np.flatnonzero(~surf.planar[surf.point_cell]), max_cos=max_cos
    )
    if faces is not None:
        on_face = (faces[0][hit] >= 0) & (faces[0][hit] == faces[1][target])
        hit, target = hit[on_face], target[on_face]
    _, first, group = np.unique(data.cell[hit] * len(surf.planar) + target, return_index=True, return_inverse=True)
    share = len(np.unique(hit)) / len(data.xyz_m)
    return HitMatches(hit, target, group, data.cell[hit[first]]), share


def linearize_hits(
    data: DenseData, mapping: LineMapping, surf: Surfels, noise: SensorNoise, m: HitMatches
) -> Linearized:
    """The groups' residuals at ``mapping``: mean ``r`` and ``J`` of each group's hits, and the
    variance of the module."""
    h, t = m.hit, m.target
    n = mapping.rotate(surf.normal_obs[t], surf.line[t])
    d = mapping.apply(data.xyz_m[h], data.line[h]) - mapping.apply(surf.anchor_obs[t], surf.line[t])
    r = np.einsum("ni,ni->n", n, d)
    var_x = normal_variance(noise, data.xyz_m[h], np.einsum("nji,nj->ni", mapping.Rt[data.line[h]], n))
    J = mapping.normal_derivative(n, data.xyz_m[h], data.line[h]) - mapping.normal_derivative(
        n, surf.anchor_obs[t], surf.line[t]
    )
    g = len(m.cell)
    k = np.bincount(m.group, minlength=g).astype(float)

    def mean(v: np.ndarray) -> np.ndarray:
        return np.bincount(m.group, v, minlength=g) / k

    t_g = np.zeros(g, dtype=np.int64)
    t_g[m.group] = t
    # The target's tilt is common to its group: it enters at the group's mean in-plane offset.
    along = d - r[:, None] * n
    offset2 = sum(mean(along[:, i]) ** 2 for i in range(3))
    var = mean(var_x) / k + surf.var_m2[t_g] / surf.count[t_g] + offset2 * surf.normal_var_rad2[t_g]
    return Linearized(mean(r), np.stack([mean(J[:, j]) for j in range(J.shape[1])], axis=1), var)


def block_system(lin: Linearized) -> tuple[np.ndarray, np.ndarray]:
    """A block's Cauchy Newton system ``(H, g)`` (``loss_choice.newton_system``) weighed by its
    own robust scale ``s`` (its variances taken as ``s^2 var``)."""
    e, s, Jn = normalised(lin)
    H, g = newton_system(e, s, Jn, cauchy(CAUCHY_C))
    return H / s**2, g / s**2


def step(*systems: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """The Cauchy cost's Newton step from the truth over the blocks' systems (:func:`block_system`)."""
    return np.asarray(np.linalg.solve(sum(H for H, _ in systems), sum(g for _, g in systems)))


def clustered_cov(blocks: list[tuple[Linearized, np.ndarray]]) -> np.ndarray:
    """That step's covariance: the Cauchy sandwich clustered by each residual's source cell
    (``covariance.sandwich``), each block's variances at its own scale."""
    scaled = [(b, c, normalised(b)[1]) for b, c in blocks]
    return sandwich(
        np.vstack([b.J for b, _, _ in scaled]),
        np.concatenate([b.r for b, _, _ in scaled]),
        np.concatenate([b.var * s**2 for b, _, s in scaled]),
        CAUCHY_C,
        np.unique(np.concatenate([c for _, c, _ in scaled]), return_inverse=True)[1],
        None,
    )


def case(
    name: str, distance_m: float, seed: int, size: int, *, oracle: bool, max_cos: float | None = None
) -> tuple[dict[str, list[float]], float, float]:
    tc = truth_case(name, distance_m, seed, size)
    data, mapping, surf, noise = tc.data, tc.mapping, tc.surf, tc.scene.scanner.noise
    bound, x = tc.bound, mapping.x
    pair_matches, pairs = last_stage_matches(data, mapping, surf, noise)
    hm, share = match_hits(data, mapping, surf, noise, max_cos=max_cos)
    groups = linearize_hits(data, mapping, surf, noise, hm)
    p, g = (pairs, pair_matches.src), (groups, hm.cell)
    sys_p, sys_g = block_system(pairs), block_system(groups)
    out = {
        "surfel pairs": over_bound(x, bound, step(sys_p)),
        "pairs + hit groups": over_bound(x, bound, step(sys_p, sys_g)),
        "hit groups alone": over_bound(x, bound, step(sys_g)),
        "sigma: pairs": over_bound(x, bound, clustered_cov([p])),
        "sigma: pairs + hit groups": over_bound(x, bound, clustered_cov([p, g])),
        "sigma: hit groups alone": over_bound(x, bound, clustered_cov([g])),
    }
    if oracle:
        hit_face = face_of_hits(tc.scene, tc.motion, tc.sim.reference_m)[0]
        if data.kept is not None:
            hit_face = hit_face[data.kept]
        faces = (hit_face, majority_face(surf.point_cell, hit_face, len(surf.planar)))
        on_face = match_hits(data, mapping, surf, noise, faces=faces, max_cos=max_cos)[0]
        same = linearize_hits(data, mapping, surf, noise, on_face)
        sys_same = block_system(same)
        out["pairs + hit groups on the target's face"] = over_bound(x, bound, step(sys_p, sys_same))
        out["hit groups on the target's face alone"] = over_bound(x, bound, step(sys_same))
    return out, float(np.mean(surf.planar[surf.point_cell])), share


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


class Case(TypedDict):
    """One case's designs (label: the four errors / bound) and shares of the hits used."""

    shape: str
    distance_m: float
    seed: int
    designs: dict[str, list[float]]
    planar: float
    share: float


def run_cases(args: argparse.Namespace) -> list[Case]:
    cases: list[Case] = []
    for name in args.shapes:
        for distance in args.distances:
            for seed in range(args.first_seed, args.first_seed + args.motions):
                designs, planar, share = case(name, distance, seed, args.size, oracle=args.oracle, max_cos=args.grazing)
                cases.append(
                    {
                        "shape": name,
                        "distance_m": distance,
                        "seed": seed,
                        "designs": designs,
                        "planar": planar,
                        "share": share,
                    }
                )
                print(f"  {name} {distance:g} m seed {seed} done", flush=True)
    return cases


def loaded(paths: list[str]) -> list[Case]:
    return [c for path in paths for c in json.loads(Path(path).read_text())["cases"]]


def summary(cases: list[Case], baseline: list[Case]) -> list[list[str]]:
    """Per shape and design: cases, RMS error / bound, the 90 % interval of its difference from
    the pairs' (or from the same design in ``baseline``, case by case), the hits used."""
    key = {(c["shape"], c["distance_m"], c["seed"]): c for c in baseline}
    rng = np.random.default_rng(0)
    rows = []
    for shape in dict.fromkeys(c["shape"] for c in cases):
        mine = [c for c in cases if c["shape"] == shape]
        planar = np.mean([c["planar"] for c in mine])
        share = np.mean([c["share"] for c in mine])
        for label in mine[0]["designs"]:
            a = np.array([c["designs"][label] for c in mine])
            if baseline:
                both = [(i, b) for i, c in enumerate(mine) if (b := key.get((c["shape"], c["distance_m"], c["seed"])))]
                both = [(i, b) for i, b in both if label in b["designs"]]
                base = np.array([b["designs"][label] for _, b in both])
                a_cmp = a[[i for i, _ in both]]
            else:
                base, a_cmp = np.array([c["designs"]["surfel pairs"] for c in mine]), a
            compare = len(base) > 0 and (baseline or not (label.startswith("sigma") or label == "surfel pairs"))
            lo, hi = paired_interval(a_cmp, base, rng) if compare else (np.nan, np.nan)
            rows.append(
                [
                    shape,
                    label,
                    str(len(a)),
                    f"{np.sqrt(np.mean(a**2)):.2f}",
                    f"{lo:+.2f} .. {hi:+.2f}",
                    f"{100 * planar:.1f} + {100 * share:.1f} %",
                ]
            )
    return rows


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
        "--grazing", type=float, default=None, metavar="COS", help="only hits seen with |cos(incidence)| below COS"
    )
    parser.add_argument(
        "--no-handover", action="store_true", help="the surfels built without handing points across edges"
    )
    parser.add_argument("--report", nargs="*", default=[], help="merge these JSON files instead of running")
    parser.add_argument("--baseline", nargs="*", default=[], help="JSON files of the same cases to compare with")
    args = parser.parse_args()
    if args.no_handover:
        # Every point stays in its own cell (the build's assign_to_faces, switched off here only).
        surfels.assign_to_faces = lambda planes, candidate, face: planes.cell.copy()
    print(machine())
    cases = loaded(args.report) if args.report else run_cases(args)
    against = "the same design in the baseline" if args.baseline else "the pairs"
    print("\nRMS over the cases and the four parameters of error / dense bound at each design's optimum from the")
    print(f"truth ('sigma': the design's own, clustered by source cell); the difference from {against},")
    print("90 % over the cases:")
    header = ["shape", "design", "cases", "RMS / bound", "difference", "hits: surfels + groups"]
    print(table(summary(cases, loaded(args.baseline)), header))
    out = out_dir()
    (out / f"{args.stem}.json").write_text(json.dumps({"cases": cases}, indent=1))
    _plot(cases, out / f"{args.stem}.png")
    print(f"wrote {out / args.stem}.json and .png")


def _plot(cases: list[Case], path: Path) -> None:
    shapes = list(dict.fromkeys(str(c["shape"]) for c in cases))
    labels = [k for k in cases[0]["designs"] if not k.startswith("sigma")]

    def rms(shape: str, label: str) -> float:
        return float(np.sqrt(np.mean(np.square([c["designs"][label] for c in cases if c["shape"] == shape]))))

    title = "The left-out hits matched to partner surfels, at the truth (lower is better)"
    with saved_figure(path, title=title, ylabel="RMS error / dense bound") as ax:
        grouped_bars(ax, shapes, {k: [rms(s, k) for s in shapes] for k in labels})
        ax.axhline(1.0, color="k", lw=0.8, ls=":")


if __name__ == "__main__":
    main()
