"""Where a bias of the dense fit comes from: the step from the truth, per patch of the target.

    python -m bench.linescan.bias_map [--shape hubble] [--distance 50] [--seed 2] [--draws 6] [--top 8]
                                      [--variant true-tube-normals|curvature-64|no-handover|
                                                 noise-free-anchors]

At the true motion, for several noise draws of one motion (noise seeds ``seed + 1000 k``): the
surfels and the last stage's matches as the refinement builds them, and one Newton step of the
Cauchy cost from the truth, ``dx = H^-1 J^T W r`` (``W`` the Cauchy weights at unit scale over
the residuals' variances, ``H = J^T diag(rho''(e) / var) J`` the cost's Hessian). Its mean over
the draws is the fit's bias to first order; its RMS, the bias and the noise together. (The
reweighted step ``(J^T W J)^-1 J^T W r`` stops short of the optimum the whole fit converges to:
its weights ``rho'(e) / e`` exceed ``rho''(e)``, by about 25 % on these residuals, and before
2026-11-29 this bench understated the steps by as much; see ``loss_choice.py``.) Each patch of
the target (the covariance's clusters: cubes of a tenth of the extent) contributes ``H^-1 J_p^T
W_p r_p``; a patch whose contribution keeps its sign in every draw (mean about as large as the
mean of its magnitudes) is a bias of that part of the surface. Sizes are in units of the dense
bound (``dense_bound.py``), per parameter (spin axis, spin rate, precession axis, precession
rate).

``--variant`` measures one change of the surfels against the same draws (the steps of both are
printed): ``true-tube-normals`` (the telescope only) puts the tube's true normals (radial from its
axis, at each anchor) in place of the pooled ones, an oracle of how much the normals' noise moves
the fit; ``curvature-64`` fits the curvature to 64 neighbours within 4 surfels (32 within 2.5);
``no-handover`` hands no points of the cells across edges to their faces' cells;
``noise-free-anchors`` takes from each surfel's anchor its points' mean noise (the simulator's
noise-free hits), so that what is left of a step is the surfels' geometry (which points, normals
and partners they have), not the noise their anchors carry.

Noise-free frames do not serve: the normals are taken from the scatter less the sensor noise's
covariance (``surfels._noise_free_normals``), which a noise-free cell does not have; on the box
that alone makes a step of 2.2 bounds.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from typing import Any

import numpy as np

from tumblescan import Motion, Scanner, Scene, random_motion
from tumblescan._typing import FloatArray
from tumblescan.linescan.dense import curvature as curvature_mod
from tumblescan.linescan.dense import surfels as surfels_mod
from tumblescan.linescan.dense.covariance import cauchy_curvature, patches
from tumblescan.linescan.dense.data import DenseData
from tumblescan.linescan.dense.mapping import LineMapping
from tumblescan.linescan.dense.matching import CAUCHY_C, cauchyweights
from tumblescan.linescan.dense.surfels import Surfels, _facing_sensor
from tumblescan.linescan.simulate import FrameCloud
from tumblescan.linescan.validation import canonical_cov
from tumblescan.target.shapes import TelescopeShape

from ..common import table
from .dense_bound import dense_bound, last_stage_matches, motion_sigmas_deg
from .real_shapes import PARAMS, UNITS, shape_named
from .reuse_diag import at_truth


def in_bounds(x: np.ndarray, delta: np.ndarray, bound: dict[str, float]) -> np.ndarray:
    """``|delta|`` in each of the four parameters over its bound (deg, deg/s alike)."""
    s = motion_sigmas_deg(x, canonical_cov(x, np.outer(delta, delta)))
    return np.array([s[p] / bound[f"{p}_{UNITS[p]}"] for p in PARAMS])


VARIANTS = ("none", "true-tube-normals", "curvature-64", "no-handover", "noise-free-anchors")
Patches = dict[tuple[int, ...], tuple[np.ndarray, int, float, np.ndarray]]


def true_tube_normals(motion: Motion, scene: Scene, mapping: LineMapping, surf: Surfels, T: float) -> Surfels:
    """``surf`` with the telescope tube's true normals (radial from its axis, the body's z) in
    place of the pooled ones, on the planar surfels whose anchors lie on the tube."""
    if not isinstance(scene.shape, TelescopeShape):
        raise ValueError("true-tube-normals is for the telescope")
    R = np.asarray(scene.R_body_to_sensor, dtype=float)
    origin = np.asarray(motion.center_m) + np.asarray(scene.body_offset_m)
    one = np.zeros(len(surf.line), dtype=np.int64)
    # Anchors at T -> at the motion's reference time -> body frame; the normals back the same way.
    to_ref = LineMapping(
        motion.at_reference(motion.reference_time_s).params(), np.array([T - motion.reference_time_s]), mapping.free
    )
    from_ref = LineMapping(mapping.x, np.array([motion.reference_time_s - T]), mapping.free)
    body = (to_ref.apply(mapping.apply(surf.anchor_obs, surf.line), one) - origin) @ R
    radius = np.hypot(body[:, 0], body[:, 1])
    shape = scene.shape
    tube = (
        surf.planar
        & (np.abs(radius - shape.tube_radius_m) < 0.06)
        & (np.abs(body[:, 2]) < shape.tube_length_m / 2 - 0.1)
    )
    n_body = np.zeros_like(body)
    n_body[tube, :2] = body[tube, :2] / radius[tube, None]
    n_T = from_ref.rotate(n_body @ R.T, one)
    n_obs = _facing_sensor(np.einsum("nji,nj->ni", mapping.Rt[surf.line], n_T), surf.anchor_obs)
    return replace(surf, normal_obs=np.where(tube[:, None], n_obs, surf.normal_obs))


def anchor_noise_m(sim: FrameCloud, data: DenseData, surf: Surfels) -> FloatArray:
    """The noise each surfel's anchor carries, ``(m, 3)`` (sensor frame, m): the mean over its
    points of the simulator's noise (measured less noise-free hit). Points of one surfel lie within
    a few lines, over which the target turns by far less than the noise."""
    kept = slice(None) if data.kept is None else data.kept
    noise_m = (sim.xyz_m - sim.xyz_true_m)[kept]
    m = len(surf.planar)
    count = np.maximum(np.bincount(surf.point_cell, minlength=m), 1)
    return (
        np.stack([np.bincount(surf.point_cell, noise_m[:, i], minlength=m) for i in range(3)], axis=1) / count[:, None]
    )


def variant_surfels(
    variant: str, motion: Motion, scene: Scene, noise_seed: int
) -> tuple[FrameCloud, DenseData, LineMapping, Surfels]:
    """The frames at the truth and their surfels, as the estimator builds them or with ``variant``."""
    if variant == "curvature-64":
        with _patched(curvature_mod, CURVATURE_NEIGHBOURS=64), _patched(surfels_mod, CURVATURE_RADIUS=4.0):
            return at_truth(motion, scene, noise_seed)
    if variant == "no-handover":
        with _patched(surfels_mod, assign_to_faces=lambda planes, givers, planar: planes.cell.copy()):
            return at_truth(motion, scene, noise_seed)
    sim, data, mapping, surf = at_truth(motion, scene, noise_seed)
    if variant == "true-tube-normals":
        surf = true_tube_normals(motion, scene, mapping, surf, float(sim.t_s.min()))
    if variant == "noise-free-anchors":
        surf = replace(surf, anchor_obs=surf.anchor_obs - anchor_noise_m(sim, data, surf))
    return sim, data, mapping, surf


@contextmanager
def _patched(module: Any, **values: Any) -> Iterator[None]:
    saved = {k: getattr(module, k) for k in values}
    for k, v in values.items():
        setattr(module, k, v)
    try:
        yield
    finally:
        for k, v in saved.items():
            setattr(module, k, v)


def steps(
    name: str, distance_m: float, seed: int, draws: int, variant: str = "none"
) -> tuple[np.ndarray, list[Patches], np.ndarray, dict[str, float]]:
    """Per draw: the whole step ``(9,)`` and each patch's ``(contribution, residuals, mean e,
    centre at T)``, keyed by the patch's cube; the truth and the bound."""
    motion = random_motion(np.random.default_rng(seed), distance_m=distance_m)
    scene = Scene(scanner=Scanner(lines=512, pixels=512), shape=shape_named(name))
    totals, per_patch = [], []
    for draw in range(draws):
        sim, data, mapping, surf = variant_surfels(variant, motion, scene, seed + 1000 * draw)
        if draw == 0:
            bound = dense_bound(motion, scene, sim, float(sim.t_s.min()))
        mt, lin = last_stage_matches(data, mapping, surf, scene.scanner.noise)
        e = lin.r / np.sqrt(lin.var)
        w = cauchyweights(e, 1.0) / lin.var
        Hinv = np.linalg.inv(lin.J.T @ (lin.J * (cauchy_curvature(e, CAUCHY_C) / lin.var)[:, None]))
        totals.append(Hinv @ (lin.J.T @ (w * lin.r)))
        anchor_T = mapping.apply(surf.anchor_obs[mt.src], surf.line[mt.src])
        cube = data.extent_m / 10
        cluster = patches(anchor_T, cube)
        found: Patches = {}
        for k in range(int(cluster.max()) + 1):
            m = cluster == k
            centre = anchor_T[m].mean(axis=0)
            key = tuple(int(v) for v in np.floor(centre / cube))
            found[key] = (Hinv @ (lin.J[m].T @ (w[m] * lin.r[m])), int(m.sum()), float(e[m].mean()), centre)
        per_patch.append(found)
    return np.array(totals), per_patch, mapping.x, bound


def summary(label: str, totals: np.ndarray, x: np.ndarray, bound: dict[str, float]) -> list[list[str]]:
    """Rows of the steps' mean (the bias) and RMS over the draws, over the bound."""
    mean = in_bounds(x, totals.mean(axis=0), bound)
    rms = np.sqrt(np.mean([in_bounds(x, t, bound) ** 2 for t in totals], axis=0))
    return [
        [f"{label} mean (bias)".strip(), *(f"{v:.2f}" for v in mean)],
        [f"{label} RMS".strip(), *(f"{v:.2f}" for v in rms)],
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--shape", default="hubble")
    parser.add_argument("--distance", type=float, default=50.0)
    parser.add_argument("--seed", type=int, default=2)
    parser.add_argument("--draws", type=int, default=6)
    parser.add_argument("--top", type=int, default=8)
    parser.add_argument("--variant", choices=VARIANTS, default="none")
    args = parser.parse_args()
    totals, per_patch, x, bound = steps(args.shape, args.distance, args.seed, args.draws)
    print(f"{args.shape} {args.distance:g} m seed {args.seed}, {args.draws} noise draws; step from the truth / bound")
    summaries = summary("", totals, x, bound)
    if args.variant != "none":
        varied = steps(args.shape, args.distance, args.seed, args.draws, args.variant)[0]
        summaries += summary(args.variant, varied, x, bound)
    print(table(summaries, ["", *PARAMS]))
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
