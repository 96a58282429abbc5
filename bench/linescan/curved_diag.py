"""Where the dense fit's information goes on curved and thin shapes, at the true motion.

    python -m bench.linescan.curved_diag [--shapes telescope dish-boom] [--seeds 0 1] [--distances 50]

Per case: the simulated frames, the surfels built at the true motion as the estimator builds
them, and the refinement started at the truth (all three stages). Prints, per part of the
shape's mesh (tube, door, wings, booms, dishes, bus: the parametric shape's build calls), the
hits, the share of them in planar surfels, and the bound of the hits of that part alone; then
per parameter the refinement's error, its reported sigma, the sigma of the plain Hessian
(``s^2 A^-1``, no clustering), the bound of every hit and of the hits in planar surfels.
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from tumblescan import Scanner, Scene, random_motion
from tumblescan.linescan.dense.covariance import cauchy_curvature, patches, sandwich
from tumblescan.linescan.dense.mapping import LineMapping
from tumblescan.linescan.dense.matching import CAUCHY_C, weights
from tumblescan.linescan.dense.refine import refine_dense
from tumblescan.linescan.dense.surfels import build_surfels
from tumblescan.target import shapes as shapes_mod

from ..common import table
from .dense_bound import _body_frame, dense_bound, face_of_hits, last_stage_matches, motion_sigmas_deg
from .real_shapes import shape_named
from .truth import frames_at_truth

PARAMS = ("spin_axis", "spin_rate", "precession_axis", "precession_rate")
UNIT = ("deg", "deg_s", "deg", "deg_s")


def part_of_triangles(shape: Any) -> tuple[list[str], np.ndarray]:
    """The build call (part name) of each triangle of a parametric shape's mesh."""
    names: list[str] = []
    counts: list[int] = []
    originals = {}
    for method in ("box", "cylinder", "dish", "beam", "plate"):
        originals[method] = getattr(shapes_mod._Parts, method)

        def wrapped(self: Any, *a: Any, _m: str = method, **k: Any) -> None:
            originals[_m](self, *a, **k)
            names.append(_m)
            counts.append(len(self.mesh.triangles))

        setattr(shapes_mod._Parts, method, wrapped)
    try:
        shape.build()
    finally:
        for method, fn in originals.items():
            setattr(shapes_mod._Parts, method, fn)
    part = np.zeros(counts[-1], dtype=np.int64)
    start = 0
    for i, end in enumerate(counts):
        part[start:end] = i
        start = end
    return [f"{i}:{n}" for i, n in enumerate(names)], part


def part_of_hits(scene: Scene, motion: Any, sim: Any, part_of_tri: np.ndarray) -> np.ndarray:
    from tumblescan._open3d import load_open3d

    o3d = load_open3d()
    mesh = scene.shape.mesh()
    vertices = np.asarray(mesh.vertices, dtype=np.float32)
    triangles = np.asarray(mesh.triangles, dtype=np.uint32)
    body, _ = _body_frame(scene, motion, sim.reference_m)
    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(o3d.core.Tensor(vertices), o3d.core.Tensor(triangles))
    tri = rc.compute_closest_points(o3d.core.Tensor(body.astype(np.float32)), nthreads=0)["primitive_ids"].numpy()
    tri = tri.astype(np.int64)
    return np.where(tri < len(triangles), part_of_tri[np.minimum(tri, len(triangles) - 1)], -1)


def errors_deg(x: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    from tumblescan.geometry.rotations import axis_from_angles

    def ang(a: np.ndarray, b: np.ndarray) -> float:
        return float(np.degrees(np.arccos(np.clip(abs(float(a @ b)), -1, 1))))

    return {
        "spin_axis": ang(axis_from_angles(x[0], x[1]), axis_from_angles(truth[0], truth[1])),
        "spin_rate": float(np.degrees(abs(abs(x[2]) - abs(truth[2])))),
        "precession_axis": ang(axis_from_angles(x[3], x[4]), axis_from_angles(truth[3], truth[4])),
        "precession_rate": float(np.degrees(abs(abs(x[5]) - abs(truth[5])))),
    }


def case(name: str, distance_m: float, seed: int, size: int, parts: bool) -> None:
    from tumblescan.target.motion import canonical_params

    motion = random_motion(np.random.default_rng(seed), distance_m=distance_m)
    scene = Scene(scanner=Scanner(lines=size, pixels=size), shape=shape_named(name))
    sim, data, mapping = frames_at_truth(motion, scene, seed)
    T, x_true, noise = float(sim.t_s.min()), mapping.x, scene.scanner.noise
    surf = build_surfels(data, mapping, noise)
    kept = np.ones(len(sim.xyz_m), dtype=bool) if data.kept is None else data.kept
    used = np.zeros(len(sim.xyz_m), dtype=bool)
    used[kept] = surf.planar[surf.point_cell]
    print(f"\n{name} {distance_m:g} m seed {seed}: {len(sim.xyz_m)} hits, surfel {data.surfel_m:.3f} m, "
          f"{100 * used.mean():.1f} % in planar surfels at the truth")  # fmt: skip
    faces = face_of_hits(scene, motion, sim.reference_m)
    b_all = dense_bound(motion, scene, sim, T, faces=faces)
    b_used = dense_bound(motion, scene, sim, T, hits=used, faces=faces)
    if parts and hasattr(scene.shape, "build"):
        names, tri_part = part_of_triangles(scene.shape)
        part = part_of_hits(scene, motion, sim, tri_part)
        rows = []
        for i, pname in enumerate(names):
            on = part == i
            if on.sum() < 50:
                continue
            b = dense_bound(motion, scene, sim, T, hits=on, faces=faces)
            bu = dense_bound(motion, scene, sim, T, hits=on & used, faces=faces) if (on & used).sum() > 50 else None
            rows.append([pname, int(on.sum()), f"{100 * used[on].mean():.0f} %",
                         *[f"{b[f'{p}_{u}']:.4f}" for p, u in zip(PARAMS, UNIT, strict=True)],
                         *([f"{bu[f'{p}_{u}']:.4f}" for p, u in zip(PARAMS, UNIT, strict=True)]
                           if bu else ["-"] * 4)])  # fmt: skip
        print(table(rows, ["part", "hits", "used", *[f"bnd {p}" for p in PARAMS], *[f"bnd-used {p}" for p in PARAMS]]))
    fit = refine_dense(data, x_true, noise=noise)
    truth_c = canonical_params(x_true)
    # The plain Hessian's covariance at the fit (no clustering), for comparison.
    mapping_f = LineMapping(fit.x, data.tau_s, tuple(range(9)))
    surf_f = build_surfels(data, mapping_f, noise)
    err = errors_deg(fit.x, truth_c)
    sd = motion_sigmas_deg(fit.x, fit.cov)
    print(f"fit: scale {fit.scale:.2f}, residuals {fit.residuals}, surfels {fit.surfels}, points {fit.points} "
          f"({100 * fit.points / len(sim.xyz_m):.0f} %), rms {1000 * fit.rms_m:.1f} mm")  # fmt: skip
    # The fit's last stage again: every other frame, the tightest gate.
    m, lin = last_stage_matches(data, mapping_f, surf_f, noise)
    _, scale = weights(lin)
    e = lin.r / np.sqrt(lin.var)
    c = CAUCHY_C * scale
    curv = cauchy_curvature(e, c) / lin.var
    A = lin.J.T @ (lin.J * curv[:, None])
    psi = e / (1.0 + (e / c) ** 2)
    score = lin.J * (psi / np.sqrt(lin.var))[:, None]
    Ainv = np.linalg.inv(A)
    cov_iid = Ainv @ (score.T @ score) @ Ainv
    cluster = patches(mapping_f.apply(surf_f.anchor_obs[m.src], surf_f.line[m.src]), data.extent_m / 10)
    cov_jk = sandwich(lin.J, lin.r, lin.var, c, cluster, None)
    # By surfel (source cell): the clustering of one surfel's residuals only.
    cov_surf = sandwich(lin.J, lin.r, lin.var, c, np.unique(m.src, return_inverse=True)[1], None)
    from tumblescan.linescan.validation import canonical_cov

    def sd_of(cov: np.ndarray) -> dict[str, float]:
        return motion_sigmas_deg(fit.x, canonical_cov(fit.x, cov))

    extra = {"iid": sd_of(cov_iid), "jk-patch": sd_of(cov_jk), "jk-surfel": sd_of(cov_surf)}
    centroid_var = surf_f.var_m2[m.src] / surf_f.count[m.src]
    tilt_var = lin.var - centroid_var - surf_f.var_m2[m.dst] / surf_f.count[m.dst]
    print(f"residuals {len(lin.r)}, scale {scale:.2f}, patches {cluster.max() + 1}, median variance terms (mm^2): "
          f"source centroid {1e6 * np.median(centroid_var):.2f}, "
          f"tilt over offset {1e6 * np.median(tilt_var):.2f}")  # fmt: skip
    rows = []
    for p, u in zip(PARAMS, UNIT, strict=True):
        rows.append([p, f"{err[p]:.4f}", f"{sd[p]:.4f}", f"{b_all[f'{p}_{u}']:.4f}", f"{b_used[f'{p}_{u}']:.4f}",
                     f"{sd[p] / b_all[f'{p}_{u}']:.1f}", f"{err[p] / b_all[f'{p}_{u}']:.1f}",
                     *[f"{extra[k][p] / b_all[f'{p}_{u}']:.1f}" for k in extra]])  # fmt: skip
    print(table(rows, ["param", "error", "sigma", "bound all", "bound used", "sigma/bound", "error/bound",
                       *[f"{k}/bound" for k in extra]]))  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--shapes", nargs="+", default=["telescope", "dish-boom"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1])
    parser.add_argument("--distances", nargs="+", type=float, default=[50.0])
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--no-parts", action="store_true")
    args = parser.parse_args()
    for name in args.shapes:
        for d in args.distances:
            for s in args.seeds:
                case(name, d, s, args.size, not args.no_parts)


if __name__ == "__main__":
    main()
