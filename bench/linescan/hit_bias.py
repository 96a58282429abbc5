"""Which hits the surfel build selects, and how its surfels sit, against the true faces.

    python -m bench.linescan.hit_bias [--cases box:50:2 long-array:100:0] [--draws 2]

At the true motion, each hit's offset from the true plane of its face of the mesh (the plane
through its face's noise-free hits at ``T``, its normal turned towards the sensor) over the
sensor's sigma along that normal, ``z``. Every hit's noise is zero-mean, so the mean ``z`` of a
set of hits chosen without regard to the noise is zero within ``1 / sqrt(n)``; a set chosen by
the noise is not. The sets: the hits of the planar cells and of the others (cut by measured
direction), the hits the build hands from a cell that is not planar to a planar neighbour
(:func:`~tumblescan.linescan.dense.handover.assign_to_faces`), all hits in planar surfels, and the
hits left out of them. Then each planar surfel against its majority face: its anchor's offset
along the true normal (mean and RMS over its own sigma ``sqrt(v / N)``), and its normal's tilt,
over its predicted sigma and along the face in the direction away from the sensor (mean, with
its standard error: a systematic tilt shows there). A surfel's normal is pooled over its
neighbours of every frame, so the surfels' standard errors are taken by face (cluster-robust).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from tumblescan import Scanner, Scene, random_motion
from tumblescan.linescan.dense.surfels import normal_variance

from ..common import ShapeCase, add_cases, grouped_bars, machine, out_dir, saved_figure, table
from .dense_bound import face_of_hits, majority_face
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


def clustered_mean(x: np.ndarray, cluster: np.ndarray) -> tuple[float, float]:
    """The mean of ``x`` and its standard error with the values of one ``cluster`` taken as
    correlated (the cluster-robust variance ``sum_c (sum_{i in c} (x_i - mean))^2 / n^2``)."""
    m = float(x.mean())
    _, c = np.unique(cluster, return_inverse=True)
    return m, float(np.sqrt(np.sum(np.bincount(c, x - m) ** 2)) / len(x))


def case(name: str, distance_m: float, seed: int, draws: int) -> dict[str, float]:
    motion = random_motion(np.random.default_rng(seed), distance_m=distance_m)
    scene = Scene(scanner=Scanner(), shape=shape_named(name))
    noise = scene.scanner.noise
    z_of: dict[str, list[np.ndarray]] = {}
    offset, tilt2, along, face_id = [], [], [], []
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
            z_of.setdefault(label, []).append(z[sel & on])
        # The planar surfels against their majority face.
        sf = majority_face(surf.point_cell, face, len(surf.planar))
        pl = np.flatnonzero(surf.planar & (sf >= 0))
        anchor = mapping.apply(surf.anchor_obs[pl], surf.line[pl])
        n_true = normals[sf[pl]]
        offset.append(
            (np.einsum("ni,ni->n", n_true, anchor) - offsets[sf[pl]]) / np.sqrt(surf.var_m2[pl] / surf.count[pl])
        )
        # The normal's error, and its part along the face in the direction away from the sensor.
        tilt = mapping.rotate(surf.normal_obs[pl], surf.line[pl]) - n_true
        sight = anchor - mapping.apply(np.zeros_like(anchor), surf.line[pl])
        sight -= np.einsum("ni,ni->n", sight, n_true)[:, None] * n_true
        sight /= np.maximum(np.linalg.norm(sight, axis=1), 1e-12)[:, None]
        tilt2.append(np.sum(tilt**2, axis=1) / surf.normal_var_rad2[pl])
        along.append(np.einsum("ni,ni->n", tilt, sight))
        face_id.append(sf[pl] + 1_000_000 * draw)  # a face of one draw is one cluster
    out: dict[str, float] = {}
    for label, zs in z_of.items():
        z_all = np.concatenate(zs)  # each hit's noise its own: independent
        out[f"{label}: hits a draw"] = len(z_all) / draws
        out[f"{label}: mean z"] = float(z_all.mean())
        out[f"{label}: mean z / SE"] = float(z_all.sum() / np.sqrt(len(z_all)))
    # A surfel's normal is pooled over its neighbours of every frame: the surfels of one face are
    # not independent, and their standard errors are taken by face.
    clusters = np.concatenate(face_id)
    m, se = clustered_mean(np.concatenate(offset), clusters)
    out["anchor offset / sigma: mean"] = m
    out["anchor offset / sigma: mean / SE (by face)"] = m / se
    out["anchor offset / sigma: RMS"] = float(np.sqrt(np.mean(np.concatenate(offset) ** 2)))
    out["normal tilt / sigma: RMS (1.41 if isotropic)"] = float(np.sqrt(np.mean(np.concatenate(tilt2))))
    m, se = clustered_mean(np.concatenate(along), clusters)
    out["normal tilt along the face, away from the sensor: mean (mdeg)"] = float(np.degrees(m) * 1e3)
    out["normal tilt along the face, away from the sensor: mean / SE (by face)"] = m / se
    out["faces"] = float(len(np.unique(clusters)))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_cases(parser, ShapeCase("box", 50, 2), ShapeCase("long-array", 100, 0))
    parser.add_argument("--draws", type=int, default=2, help="noise draws per case (seeds seed, seed + 1000, ...)")
    parser.add_argument("--stem", default="hit_bias")
    args = parser.parse_args()
    print(machine())
    results = {}
    for spec in args.cases:
        results[str(spec)] = case(spec.name, spec.distance_m, spec.seed, args.draws)
        print(f"  {spec} done", flush=True)
    keys = list(next(iter(results.values())))
    print(f"\nAt the true motion, {args.draws} noise draws a case:")
    print(table([[k, *(f"{results[c][k]:.4g}" for c in results)] for k in keys], ["", *results]))
    out = out_dir()
    (out / f"{args.stem}.json").write_text(json.dumps(results, indent=1))
    _plot(results, out / f"{args.stem}.png")
    print(f"wrote {out / args.stem}.json and .png")


def _plot(results: dict[str, dict[str, float]], path: Path) -> None:
    keys = [k for k in next(iter(results.values())) if "/ SE" in k]
    names = [k.split(": mean")[0] for k in keys]
    title = "Hit sets and surfels against the true faces (|value| > 2: not noise)"
    with saved_figure(path, title=title, ylabel="mean over its standard error") as ax:
        grouped_bars(ax, names, {spec: [r[k] for k in keys] for spec, r in results.items()})
        for label in ax.get_xticklabels():
            label.set_rotation(25)
            label.set_horizontalalignment("right")
        for y in (-2, 2):
            ax.axhline(y, color="k", lw=0.8, ls=":")


if __name__ == "__main__":
    main()
