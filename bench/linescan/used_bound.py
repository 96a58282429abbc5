"""Where the information the fit leaves out lies: the dense bound of the hits each design uses,
over the bound of every hit, at the true motion.

    python -m bench.linescan.used_bound [--cases dish-boom:100:5 long-array:100:14 ...] [--stem NAME]

The dense bound (``dense_bound.bound_covariances``: every face of the mesh a nuisance plane,
each hit with its own sensor noise) of a subset of the hits is what an efficient estimator using
only those hits could reach; over the bound of all hits it says how much the rest carry. Per
case (a seeded motion of ``real_shapes``, its surfels built at the true motion as the estimator
builds them), the hits of growing sets:

- ``planar surfels``: the hits in planar surfels (with those handed to them across edges);
- ``+ members``: and the thin members' hits (``find_beams``);
- ``the fit``: and the grazing groups' hits (``find_grazing``): what the last stage uses;
- ``+ steep sight``: and the left-out hits matched by their line of sight at steep incidence
  (``sight_match``'s "grazing + steep sight");
- ``+ grazing candidates``: and every hit the grazing groups were tried on
  (``grazing.grazing_candidates``), matched or not;
- ``+ rest outside hand-over cells``: and every other hit, but those left in cells that handed
  points to a planar neighbour (``handover.assign_to_faces``);
- ``all``: every hit (1 by construction).

A hit counts as used when the design matches it in at least one other frame: the bound does not
ask how often. Prints per case and set the share of the hits and the bound's ratio for the four
rotation parameters; writes JSON and a plot of the ratios' RMS per set and case.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from tumblescan import Motion, Scanner, Scene, random_motion
from tumblescan.linescan.dense.beams import find_beams
from tumblescan.linescan.dense.grazing import MAX_COS_INCIDENCE, find_grazing, grazing_candidates

from ..common import ShapeCase, add_cases, grouped_bars, machine, out_dir, saved_figure, table
from .dense_bound import bound_covariances, face_of_hits, motion_sigmas_deg
from .real_shapes import shape_named
from .reuse_diag import at_truth
from .sight_match import match_by_sight

SETS = (
    "planar surfels",
    "+ members",
    "the fit",
    "+ steep sight",
    "+ grazing candidates",
    "+ rest outside hand-over cells",
    "all",
)
PARAMS = ("spin_axis", "spin_rate", "precession_axis", "precession_rate")


def hit_sets(motion: Motion, scene: Scene, noise_seed: int) -> tuple[dict[str, NDArray[np.bool_]], dict[str, float]]:
    """The sets' hits ``(n,)`` over the points the estimator keeps (see the module), and the
    bound's ratio per set and rotation parameter (``{set}: {param}``)."""
    noise = scene.scanner.noise
    sim, data, mapping, surf = at_truth(motion, scene, noise_seed)
    kept = np.flatnonzero(np.ones(len(sim.xyz_m), dtype=bool) if data.kept is None else data.kept)
    used = surf.planar[surf.point_cell]
    sets = {SETS[0]: used.copy()}
    beams = find_beams(data, mapping, surf, noise)
    used[beams.point] = True
    sets[SETS[1]] = used.copy()
    used[find_grazing(data, mapping, surf, noise, exclude=beams.point).hit] = True
    sets[SETS[2]] = used.copy()
    left_out = np.flatnonzero(~surf.planar[surf.point_cell])
    used[match_by_sight(data, mapping, surf, noise, left_out, min_cos=MAX_COS_INCIDENCE)[0]] = True
    sets[SETS[3]] = used.copy()
    used[grazing_candidates(data, surf)] = True
    sets[SETS[4]] = used.copy()
    handed = np.zeros(len(surf.planar), dtype=bool)
    handed[data.cell[surf.point_cell != data.cell]] = True
    used |= ~handed[data.cell]
    sets[SETS[5]] = used.copy()
    sets[SETS[6]] = np.ones(len(used), dtype=bool)
    faces = face_of_hits(scene, motion, sim.reference_m)
    reference_s = float(sim.t_s.min())
    out: dict[str, float] = {}
    full: np.ndarray | None = None
    for label in reversed(SETS):
        hits = np.zeros(len(sim.xyz_m), dtype=bool)
        hits[kept[sets[label]]] = True
        b = bound_covariances(motion, scene, sim, reference_s, hits=hits, faces=faces)
        sd = np.array([motion_sigmas_deg(b.x, b.facets)[p] for p in PARAMS])
        full = sd if full is None else full
        out.update({f"{label}: {p}": float(v) for p, v in zip(PARAMS, sd / full, strict=True)})
    return sets, out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_cases(
        parser,
        ShapeCase("dish-boom", 100, 5),
        ShapeCase("long-array", 100, 14),
        ShapeCase("octagon-truss", 50, 2),
        ShapeCase("hubble", 50, 4),
        ShapeCase("box", 50, 2),
    )
    parser.add_argument("--stem", default="used_bound")
    args = parser.parse_args()
    print(machine())
    results: dict[str, dict[str, float]] = {}
    rows = []
    for spec in args.cases:
        motion = random_motion(np.random.default_rng(spec.seed), distance_m=spec.distance_m)
        sets, ratios = hit_sets(motion, Scene(scanner=Scanner(), shape=shape_named(spec.name)), spec.seed)
        results[str(spec)] = {**ratios, **{f"{label}: hits": float(hits.mean()) for label, hits in sets.items()}}
        for label, hits in sets.items():
            rows.append([str(spec), label, f"{hits.mean():.3f}", *(f"{ratios[f'{label}: {p}']:.2f}" for p in PARAMS)])
        print(f"{spec} done", flush=True)
    print("\nThe bound of each set's hits over the bound of every hit (1: they hold all the information)")
    print(table(rows, ["case", "hits", "share of hits", *PARAMS]))
    path = out_dir() / f"{args.stem}.json"
    path.write_text(json.dumps(results, indent=1))
    _plot(results, path.with_suffix(".png"))
    print(f"wrote {path} and .png")


def _plot(results: dict[str, dict[str, float]], path: Path) -> None:
    """Per case and set, the RMS over the four rotation parameters of the bound's ratio."""
    cases = list(results)
    series = {
        label: [float(np.sqrt(np.mean([results[c][f"{label}: {p}"] ** 2 for p in PARAMS]))) for c in cases]
        for label in SETS[:-1]
    }
    with saved_figure(
        path, title="Bound of the hits used over the bound of all hits", ylabel="ratio (RMS over 4 parameters)"
    ) as ax:
        grouped_bars(ax, cases, series)
        ax.axhline(1.0, color="grey", linewidth=0.8)


if __name__ == "__main__":
    main()
