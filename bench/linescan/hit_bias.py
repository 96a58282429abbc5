"""Which hits the surfel build selects, and how its surfels sit, against the true faces.

    python -m bench.linescan.hit_bias [--cases box:50:2 long-array:100:0] [--draws 2]

At the true motion, each hit's offset from the true plane of its face of the mesh (the plane
through its face's noise-free hits at ``T``, its normal turned towards the sensor) over the
sensor's sigma along that normal, ``z``. Every hit's noise is zero-mean, so the mean ``z`` of a
set of hits chosen without regard to the noise is zero within ``1 / sqrt(n)``; a set chosen by
the noise is not. The sets: the hits of the planar cells and of the others (cut by measured
direction), the hits the build hands from a cell that is not planar to a planar neighbour
(:func:`~tumblescan.linescan.dense.faces.assign_to_faces`), all hits in planar surfels, and the
hits left out of them. Then each planar surfel against its majority face: its anchor's offset
along the true normal (mean and RMS over its own sigma ``sqrt(v / N)``), and its normal's tilt,
over its predicted sigma and along the in-plane direction of the line of sight (mean, with its
standard error: a systematic tilt shows there).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from tumblescan import Scanner, Scene, random_motion
from tumblescan.linescan.dense.surfels import normal_variance

from ..common import machine, out_dir, table
from .dense_bound import face_of_hits
from .hit_pairs import majority_face
from .real_shapes import shape_named
from .reuse_diag import at_truth


def true_planes(face: np.ndarray, points_T: np.ndarray, sensor_T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each face's unit normal ``(faces, 3)``, turned towards the sensor on the whole, and offset
    ``(faces,)``, from its noise-free hits at ``T`` (rows of ``face < 0`` are left out)."""
    nf = int(face.max()) + 1
    normals, offsets = np.zeros((nf, 3)), np.zeros(nf)
    for f in range(nf):
        on = face == f
        if np.sum(on) < 3:
            continue
        q = points_T[on]
        c = q.mean(axis=0)
        n = np.linalg.eigh((q - c).T @ (q - c))[1][:, 0]
        n = n if np.sum((sensor_T[on] - q) @ n) >= 0 else -n
        normals[f], offsets[f] = n, n @ c
    return normals, offsets


def case(name: str, distance_m: float, seed: int, draws: int) -> dict[str, float]:
    motion = random_motion(np.random.default_rng(seed), distance_m=distance_m)
    scene = Scene(scanner=Scanner(), shape=shape_named(name))
    noise = scene.scanner.noise
    sums: dict[str, list[float]] = {}
    for draw in range(draws):
        sim, data, mapping, surf = at_truth(motion, scene, seed + 1000 * draw)
        kept = np.ones(len(sim.xyz_m), dtype=bool) if data.kept is None else data.kept
        face = face_of_hits(scene, motion, sim.reference_m)[0][kept]
        points_T = mapping.apply(sim.xyz_true_m[kept], data.line)
        sensor_T = mapping.apply(np.zeros_like(points_T), data.line)
        normals, offsets = true_planes(face, points_T, sensor_T)
        on = face >= 0
        n = normals[np.maximum(face, 0)]
        r = np.einsum("ni,ni->n", n, mapping.apply(data.xyz_m, data.line)) - offsets[np.maximum(face, 0)]
        z = r / np.sqrt(normal_variance(noise, data.xyz_m, np.einsum("nji,nj->ni", mapping.Rt[data.line], n)))
        in_surfel, in_cell = surf.planar[surf.point_cell], surf.planar[data.cell]
        sets = {
            "planar cells": in_cell,
            "cells not planar": ~in_cell,
            "handed over": in_surfel & ~in_cell,
            "in planar surfels": in_surfel,
            "left out": ~in_surfel,
        }
        for label, sel in sets.items():
            sums.setdefault(f"{label}: sum z", []).append(float(z[sel & on].sum()))
            sums.setdefault(f"{label}: hits", []).append(float(np.sum(sel & on)))
        # The planar surfels against their majority face.
        sf = majority_face(surf.point_cell, face, len(surf.planar))
        pl = np.flatnonzero(surf.planar & (sf >= 0))
        anchor = mapping.apply(surf.anchor_obs[pl], surf.line[pl])
        normal = mapping.rotate(surf.normal_obs[pl], surf.line[pl])
        n_true = normals[sf[pl]]
        off = (np.einsum("ni,ni->n", n_true, anchor) - offsets[sf[pl]]) / np.sqrt(surf.var_m2[pl] / surf.count[pl])
        sight = anchor - mapping.apply(np.zeros_like(anchor), surf.line[pl])
        sight -= np.einsum("ni,ni->n", sight, n_true)[:, None] * n_true
        sight /= np.maximum(np.linalg.norm(sight, axis=1), 1e-12)[:, None]
        tilt = normal - n_true
        along = np.einsum("ni,ni->n", tilt, sight)
        sums.setdefault("anchors: sum", []).append(float(off.sum()))
        sums.setdefault("anchors: sum sq", []).append(float(np.sum(off**2)))
        sums.setdefault("anchors", []).append(float(len(pl)))
        sums.setdefault("tilt over sigma: sum sq", []).append(
            float(np.sum(np.sum(tilt**2, axis=1) / surf.normal_var_rad2[pl]))
        )
        sums.setdefault("tilt along sight: sum", []).append(float(along.sum()))
        sums.setdefault("tilt along sight: sum sq", []).append(float(np.sum(along**2)))
    t = {k: float(np.sum(v)) for k, v in sums.items()}
    out: dict[str, float] = {}
    for label in sets:
        k = t[f"{label}: hits"]
        out[f"{label}: hits a draw"] = k / draws
        out[f"{label}: mean z"] = t[f"{label}: sum z"] / k
        out[f"{label}: mean z / SE"] = t[f"{label}: sum z"] / np.sqrt(k)
    k = t["anchors"]
    out["anchor offset / sigma: mean"] = t["anchors: sum"] / k
    out["anchor offset / sigma: mean / SE"] = t["anchors: sum"] / np.sqrt(k)
    out["anchor offset / sigma: RMS"] = float(np.sqrt(t["anchors: sum sq"] / k))
    out["normal tilt / sigma: RMS (2 dof: 1.41)"] = float(np.sqrt(t["tilt over sigma: sum sq"] / k))
    mean_along = t["tilt along sight: sum"] / k
    sd_along = np.sqrt(t["tilt along sight: sum sq"] / k - mean_along**2)
    out["normal tilt along the sight: mean (mdeg)"] = float(np.degrees(mean_along) * 1e3)
    out["normal tilt along the sight: mean / SE"] = float(mean_along / (sd_along / np.sqrt(k)))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cases", nargs="+", default=["box:50:2", "long-array:100:0"], help="shape:distance_m:seed")
    parser.add_argument("--draws", type=int, default=2, help="noise draws per case (seeds seed, seed + 1000, ...)")
    parser.add_argument("--stem", default="hit_bias")
    args = parser.parse_args()
    print(machine())
    results = {}
    for spec in args.cases:
        name, distance, seed = spec.split(":")
        results[spec] = case(name, float(distance), int(seed), args.draws)
        print(f"  {spec} done", flush=True)
    keys = list(next(iter(results.values())))
    print(f"\nAt the true motion, {args.draws} noise draws a case:")
    print(table([[k, *(f"{results[c][k]:.4g}" for c in results)] for k in keys], ["", *results]))
    out = out_dir()
    (out / f"{args.stem}.json").write_text(json.dumps(results, indent=1))
    _plot(results, out / f"{args.stem}.png")
    print(f"wrote {out / args.stem}.json and .png")


def _plot(results: dict[str, dict[str, float]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keys = [k for k in next(iter(results.values())) if k.endswith("/ SE")]
    fig, ax = plt.subplots(figsize=(9, 4.5))
    width = 0.8 / len(results)
    for i, (spec, r) in enumerate(results.items()):
        ax.bar(np.arange(len(keys)) + (i - (len(results) - 1) / 2) * width, [r[k] for k in keys], width, label=spec)
    for y in (-2, 2):
        ax.axhline(y, color="k", lw=0.8, ls=":")
    ax.set_xticks(
        np.arange(len(keys)), [k.replace(" / SE", "").replace(": mean", "") for k in keys], rotation=25, ha="right"
    )
    ax.set_ylabel("mean over its standard error")
    ax.set_title("Hit sets and surfels against the true faces (|value| > 2: not noise)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
