"""Planar surfels across a mesh edge (issue 20): which the face tests admit, and what a rule
against them would remove, measured at the true motion against the simulator's faces.

    python -m bench.linescan.straddle_diag capture --cases octagon-truss:50:7 box:100:2
    python -m bench.linescan.straddle_diag rules

``capture``: one noisy seeded case each (the bench's frames), the surfels built at the true
motion, the inputs of ``faces.inside_face`` / ``faces.beside_face`` and each kept point's mesh
face; one pickle per case in ``bench/out``. ``rules``: per case and candidate rule, the share of
the straddlers (planar cells, after the handover, holding points of two or more faces) that
the rule removes and of the other planar cells it loses.
"""

from __future__ import annotations

import argparse
import pickle
from pathlib import Path
from typing import Any

import numpy as np

from tumblescan import Scanner, Scene, random_motion
from tumblescan.linescan.dense import faces as faces_mod
from tumblescan.linescan.dense import surfels as surfels_mod

from ..common import ShapeCase, add_cases, out_dir, table
from .dense_bound import face_of_hits
from .real_shapes import shape_named
from .truth import frames_at_truth


def capture(name: str, distance_m: float, seed: int, size: int, rules_off: bool = False) -> dict[str, Any]:
    motion = random_motion(np.random.default_rng(seed), distance_m=distance_m)
    scene = Scene(scanner=Scanner(lines=size, pixels=size), shape=shape_named(name))
    sim, data, mapping = frames_at_truth(motion, scene, seed)
    noise = scene.scanner.noise
    rec: dict[str, Any] = {}
    inside, beside = surfels_mod.inside_face, surfels_mod.beside_face

    def inside_rec(neighbours: Any, normal_obs: Any, count: Any, flat: Any, tilt: Any, interior: Any) -> Any:
        out = inside(neighbours, normal_obs, count, flat, tilt, interior)
        rec.update(normal_obs=normal_obs, flat=flat, inside=flat & interior & out)
        return out

    def beside_rec(planes: Any, candidate: Any, face: Any) -> Any:
        out = beside(planes, candidate, face)
        rec.update(planes=planes, beside=out)
        return out

    other, outline = surfels_mod.clear_of_other_faces, surfels_mod.clear_of_outlines
    surfels_mod.inside_face, surfels_mod.beside_face = inside_rec, beside_rec  # type: ignore[assignment]
    if rules_off:
        surfels_mod.clear_of_other_faces = lambda planes, cells, other: cells
        surfels_mod.clear_of_outlines = lambda neighbours, count, interior, cells: cells
    try:
        surf = surfels_mod.build_surfels(data, mapping, noise)
    finally:
        surfels_mod.inside_face, surfels_mod.beside_face = inside, beside
        surfels_mod.clear_of_other_faces, surfels_mod.clear_of_outlines = other, outline
    kept = np.arange(len(sim.xyz_m)) if data.kept is None else np.flatnonzero(data.kept)
    face = face_of_hits(scene, motion, sim.reference_m)[0][kept]
    return {"case": (name, distance_m, seed), "neighbours": data.neighbours, "interior": data.interior,
            "cell": data.cell, "xyz_obs": data.xyz_m, "point_cell": surf.point_cell, "planar": surf.planar,
            "face": face,
            "range_sigma_m": noise.range_sigma_m, "n_input": len(sim.xyz_m), **rec}  # fmt: skip


def one_face(cell: np.ndarray, face: np.ndarray, m: int) -> np.ndarray:
    lo = np.full(m, np.iinfo(np.int64).max)
    hi = np.full(m, -2)
    np.minimum.at(lo, cell, face)
    np.maximum.at(hi, cell, face)
    return np.asarray((lo == hi) & (lo >= 0))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("mode", choices=["capture", "rules"])
    add_cases(parser, ShapeCase("octagon-truss", 50, 7))
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--tags", nargs="+", default=["off", "on"], help="rules: the captures to compare")
    parser.add_argument("--tag", default="on", help="capture: the pickles' tag (off: without the two rules)")
    args = parser.parse_args()
    if args.mode == "capture":
        for c in args.cases:
            name, d, s = c
            out = capture(name, d, s, args.size, rules_off=args.tag == "off")
            (out_dir() / f"straddle_{args.tag}_{name}_{d:g}_{s}.pkl").write_bytes(pickle.dumps(out))
            print(c, "done", flush=True)
        return
    rules(sorted(out_dir().glob("straddle_off_*.pkl")))
    effect(args.tags)


def effect(tags: list[str]) -> None:
    """Per case, per capture tag: planar cells, those holding points of two or more faces
    (after the handover), the points in them not on the cell's main face, and the share of the
    points in planar cells."""
    rows = []
    for path in sorted(out_dir().glob(f"straddle_{tags[0]}_*.pkl")):
        row: list[object] = []
        for t in tags:
            c = pickle.loads(path.with_name(path.name.replace(f"_{tags[0]}_", f"_{t}_")).read_bytes())
            planar, cell, face = c["planar"], c["point_cell"], c["face"]
            m = len(planar)
            if not row:
                row = [*c["case"][:2], c["case"][2]]
            per = np.zeros(m)
            main = np.zeros(m)
            for f in np.unique(face):
                n_f = np.bincount(cell[face == f], minlength=m)
                main = np.maximum(main, n_f)
                per += n_f
            strays = int(np.sum((per - main)[planar]))
            row.append(f"{int(planar.sum())} / {int(np.sum(planar & ~one_face(cell, face, m)))} / {strays} / "
                       f"{np.mean(planar[cell]):.3f}")  # fmt: skip
        rows.append(row)
    print(table(rows, ["shape", "m", "seed", *tags]))
    print("planar cells / of them on 2+ faces / their points off the main face / points in planar cells")


def rules(paths: list[Path]) -> None:
    """Per case (captured with the rules off) and rule: straddlers removed / good planar cells
    lost, and the share of the points in planar cells at the true motion (before the handover
    would move any more of them)."""
    rows = []
    for path in paths:
        c = pickle.loads(path.read_bytes())
        planes, planar = c["planes"], c["planar"]
        m = len(planar)
        good = one_face(c["point_cell"], c["face"], m)
        straddler, kept = planar & ~good, planar & good
        n_points = len(c["point_cell"])
        found = {
            "band, flat others": ~faces_mod.clear_of_other_faces(planes, planar, c["flat"] & c["interior"]),
            "band": ~faces_mod.clear_of_other_faces(planes, planar, planar),
            "outline": ~faces_mod.clear_of_outlines(c["neighbours"], planes.count, c["interior"], planar),
        }
        found["band + outline"] = found["band"] | found["outline"]
        cells: list[object] = [*c["case"][:2], c["case"][2], int(straddler.sum()), int(planar.sum()),
                               f"{np.mean(planar[c['point_cell']]):.3f}"]  # fmt: skip
        for out in found.values():
            share = np.sum(planar[c["point_cell"]] & ~out[c["point_cell"]]) / n_points
            cells.append(f"{np.mean(out[straddler]):.2f} / {np.mean(out[kept]):.3f} / {share:.3f}")
        rows.append(cells)
    print(table(rows, ["shape", "m", "seed", "straddlers", "planar", "points", *found]))
    print("rules: straddlers removed / other planar cells lost / points in planar cells after")


if __name__ == "__main__":
    main()
