"""The hits of flat cells on a border of the view (issue 20): what they would add, and how pure they are.

    python -m bench.linescan.border_diag [--cases long-array:100:3 box:100:2]

At the true motion (the bench's seeded motion and frames), the surfels built as the estimator
builds them. A *border* cell is not interior (a side neighbour of its frame's view not hit, or
hit at a range more than ``MAX_RANGE_STEP`` surfels away: the silhouette, an occlusion); a *flat*
one passes :func:`~tumblescan.linescan.dense.faces.flat_cells`. The estimator leaves them out,
since a partner frame sees another part there and a plane fitted to them may lean towards another
face. Per case: the dense bound (``dense_bound.py``, every mesh face a nuisance plane) of the hits
used, then with the flat border cells' hits added (all of them; only those of cells whose hits
lie 98 % or more on one face, which takes the truth; those of every flat border cell without the
part of the cell next to its bad sides, the outer third or half, where the outline runs; those of
the silhouette, of the far side of an occlusion and of its near side apart), each over the bound
of all hits; and the share of the added hits that lie off their cell's main face.
"""

from __future__ import annotations

import argparse

import numpy as np
from numpy.typing import NDArray

from tumblescan import Scanner, Scene, random_motion
from tumblescan.linescan.dense.data import MAX_RANGE_STEP, DenseData
from tumblescan.linescan.dense.faces import NEIGHBOUR_OFFSETS, SIDE_NEIGHBOURS
from tumblescan.linescan.dense.mapping import LineMapping
from tumblescan.linescan.sensor import SensorNoise, azimuth_elevation

from ..common import ShapeCase, add_cases, table
from .dense_bound import dense_bound, face_of_hits
from .line_potential import PARAMS, flat_of_cells
from .real_shapes import shape_named
from .reuse_diag import at_truth

PURE = 0.98


def flat_border(data: DenseData, mapping: LineMapping, noise: SensorNoise) -> NDArray[np.bool_]:
    """The cells ``(m,)`` that are flat and not interior."""
    return np.asarray(flat_of_cells(data, mapping, noise)[0] & ~data.interior)


def inward(data: DenseData) -> np.ndarray:
    """Each point's distance in the view, in cells, from the nearest side of its cell whose neighbour
    is missing or at a range step (9 where there is none)."""
    az, el = azimuth_elevation(data.xyz_m)
    step = data.surfel_m / float(np.median(data.range_m))
    fa, fe = (az - az.min()) / step, (el - el.min()) / step
    ua, ue = fa - np.floor(fa), fe - np.floor(fe)
    rho = data.cell_range_m
    out = np.full(len(data.xyz_m), 9.0)
    for k, (da, de) in enumerate(NEIGHBOUR_OFFSETS):
        if k not in SIDE_NEIGHBOURS:
            continue
        nb = data.neighbours[:, k]
        bad = ((nb < 0) | (np.abs(rho[np.maximum(nb, 0)] - rho) > MAX_RANGE_STEP * data.surfel_m))[data.cell]
        d = (1 - ua) if da == 1 else ua if da == -1 else (1 - ue) if de == 1 else ue
        out = np.where(bad, np.minimum(out, d), out)
    return out


def case(name: str, distance_m: float, seed: int, size: int) -> list[list[object]]:
    motion = random_motion(np.random.default_rng(seed), distance_m=distance_m)
    scene = Scene(scanner=Scanner(lines=size, pixels=size), shape=shape_named(name))
    sim, data, mapping, surf = at_truth(motion, scene, seed)
    noise, T = scene.scanner.noise, float(sim.t_s.min())
    n, m = len(sim.xyz_m), len(data.cell_frame)
    kept = np.ones(n, dtype=bool) if data.kept is None else data.kept

    def full(v: NDArray[np.bool_]) -> NDArray[np.bool_]:
        out = np.zeros(n, dtype=bool)
        out[kept] = v
        return out

    used = full(surf.planar[surf.point_cell])
    faces = face_of_hits(scene, motion, sim.reference_m)
    face = faces[0]
    cell = np.full(n, -1, dtype=np.int64)
    cell[kept] = data.cell
    on = (face >= 0) & (cell >= 0)
    pairs, cnt = np.unique(np.stack([cell[on], face[on]]), axis=1, return_counts=True)
    order = np.argsort(cnt)
    main_face = np.full(m, -1, dtype=np.int64)
    main_face[pairs[0][order]] = pairs[1][order]  # the largest count written last
    majority = np.zeros(m)
    np.maximum.at(majority, pairs[0], cnt)
    pure = majority / np.maximum(np.bincount(data.cell, minlength=m), 1) >= PURE
    border = flat_border(data, mapping, noise)
    depth = inward(data)
    # Which border: a side neighbour not hit (the silhouette), or one hit at a range step in front
    # of the cell (the cell is the far side of an occlusion) or behind it (the near side, an edge).
    side = data.neighbours[:, list(SIDE_NEIGHBOURS)]
    step = data.cell_range_m[np.maximum(side, 0)] - data.cell_range_m[:, None]
    missing = np.any(side < 0, axis=1)
    in_front = np.any((side >= 0) & (step < -MAX_RANGE_STEP * data.surfel_m), axis=1)
    behind = np.any((side >= 0) & (step > MAX_RANGE_STEP * data.surfel_m), axis=1)
    b_all = dense_bound(motion, scene, sim, T, faces=faces)
    rows: list[list[object]] = []
    for label, extra in [
        ("used", np.zeros(n, dtype=bool)),
        ("+ flat border", full(border[data.cell])),
        (f"+ flat border, {PURE:.0%} pure (truth)", full((border & pure)[data.cell])),
        ("+ flat border, inner 2/3", full(border[data.cell] & (depth > 1 / 3))),
        ("+ flat border, inner 1/2", full(border[data.cell] & (depth > 1 / 2))),
        ("+ flat silhouette", full((border & missing)[data.cell])),
        ("+ flat far side of a range step", full((border & ~missing & in_front & ~behind)[data.cell])),
        ("+ flat near side of a range step", full((border & ~missing & behind & ~in_front)[data.cell])),
    ]:
        added = extra & ~used
        off = float(np.mean(face[added & on] != main_face[cell[added & on]])) if np.any(added & on) else 0.0
        b = dense_bound(motion, scene, sim, T, hits=used | extra, faces=faces)
        rows.append([name, f"{distance_m:g}", seed, label, f"{100 * added.mean():.1f}", f"{100 * off:.1f}",
                     *[f"{b[p] / b_all[p]:.2f}" for p in PARAMS]])  # fmt: skip
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_cases(parser, ShapeCase("long-array", 100, 3), ShapeCase("box", 100, 2))
    parser.add_argument("--size", type=int, default=512)
    args = parser.parse_args()
    rows = []
    for name, distance, seed in args.cases:
        rows += case(name, distance, seed, args.size)
    header = ["shape", "m", "seed", "hits", "added %", "added off their cell's face %", *[f"{p} / all" for p in PARAMS]]
    print(table(rows, header))


if __name__ == "__main__":
    main()
