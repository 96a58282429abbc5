"""Why the dense fit's reported sigma misses on some real-shape cases: noise or bias, and the
covariance variants that would cover them.

    python -m bench.linescan.sigma_diag capture --shapes octagon-truss box --seeds 0 1 2 --distances 50 100
    python -m bench.linescan.sigma_diag draws --shapes octagon-truss --seeds 7 --distances 50 [--draws 8]
    python -m bench.linescan.sigma_diag variants bench/out/sigma_capture_*.pkl

``capture``: the bench's case (``real_shapes.one``'s seeded frames and whole estimate), with
the final fit's covariance inputs kept (residuals, Jacobian, variances, Cauchy constant, each
residual's patch and the surfel anchors the patches come from), its errors and the dense bound;
one pickle per case in ``bench/out``. ``variants`` recomputes the covariance from those inputs
by several rules and prints, per rule, the worst |error| / sigma per case, the count over 3
sigma and the median sigma / bound. ``draws``: the same motion's frames under several noise
draws (noise seeds ``seed + 1000 k``, ``k = 0`` the bench's) and noise-free, each refined from
the true motion: per parameter the signed error (axes: along the weakest direction of the
reported covariance) and the reported sigma, so that noise (RMS of the errors over the draws
above the sigmas) and bias (the noise-free error, or one sign across draws) can be told apart.
"""

from __future__ import annotations

import argparse
import pickle
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from tumblescan import Scanner, Scene, TimedCloud, estimate_from_frames, random_motion, simulate_frames
from tumblescan.geometry.rotations import axis_from_angles, axis_tangents
from tumblescan.linescan.dense import covariance as covariance_mod
from tumblescan.linescan.dense import refine as refine_mod
from tumblescan.linescan.dense import surfels as surfels_mod
from tumblescan.linescan.frames import assemble_frames
from tumblescan.linescan.validation import canonical_cov, embed
from tumblescan.target.motion import canonical_params

from ..common import out_dir, table
from .dense import errors
from .dense_bound import motion_sigmas_deg
from .real_shapes import FLOOR, PARAMS, UNITS, against_bound, shape_named
from .truth import dense_data, frames_at_truth


def sigmas(x_raw: np.ndarray, cov_free: np.ndarray, free: tuple[int, ...]) -> dict[str, float]:
    """The result's four 1-sigmas (deg, deg/s) from the free parameters' covariance at ``x_raw``."""
    return motion_sigmas_deg(canonical_params(x_raw), canonical_cov(x_raw, embed(cov_free, free)))


@contextmanager
def edge_rules(variant: str) -> Iterator[None]:
    """The surfel build without its edge rules inside the block when ``variant`` is
    ``no-edge-rules`` (``faces.clear_of_other_faces``, ``clear_of_outlines``, the outline cells'
    points kept out); restored after."""
    rules = surfels_mod.clear_of_other_faces, surfels_mod.clear_of_outlines, surfels_mod.KEEP_EDGE_POINTS_OUT
    if variant == "no-edge-rules":
        surfels_mod.clear_of_other_faces = lambda planes, cells, other: cells
        surfels_mod.clear_of_outlines = lambda neighbours, count, interior, cells: cells
        surfels_mod.KEEP_EDGE_POINTS_OUT = False
    try:
        yield
    finally:
        surfels_mod.clear_of_other_faces, surfels_mod.clear_of_outlines, surfels_mod.KEEP_EDGE_POINTS_OUT = rules


# --- capture -------------------------------------------------------------------------------


def capture(name: str, distance_m: float, seed: int, size: int, variant: str = "") -> dict[str, Any]:
    """The bench's case with the final fit's covariance inputs (see the module docstring);
    variant ``oracle-one-face``: no surfel holding points of two mesh faces (:func:`_one_face_only`)."""
    calls: list[dict[str, Any]] = []
    finish, sandwich, patches = refine_mod._finish, refine_mod.sandwich, refine_mod.patches

    def finish_rec(problem: Any, z: np.ndarray, *a: Any) -> Any:
        calls.append({"x_raw": problem.full(z), "free": problem.free})
        return finish(problem, z, *a)

    def patches_rec(anchor: np.ndarray, size_m: float) -> Any:
        calls[-1].update(anchor=anchor, patch_m=size_m)
        return patches(anchor, size_m)

    def sandwich_rec(J: np.ndarray, r: np.ndarray, var: np.ndarray, c: float, cluster: np.ndarray, g: Any) -> Any:
        out = sandwich(J, r, var, c, cluster, g)
        calls[-1].update(J=J, r=r, var=var, c=c, cluster=cluster, gauge=g, cov=out)
        return out

    motion = random_motion(np.random.default_rng(seed), distance_m=distance_m)
    scene = Scene(scanner=Scanner(lines=size, pixels=size), shape=shape_named(name))
    sim = simulate_frames(motion, scene, seed=seed)
    frames = assemble_frames(TimedCloud(sim.xyz_m, sim.t_s, {"frame": sim.frame, "line": sim.line}))
    build = refine_mod.build_surfels
    refine_mod._finish, refine_mod.sandwich, refine_mod.patches = finish_rec, sandwich_rec, patches_rec  # type: ignore[assignment]
    if variant == "oracle-one-face":
        refine_mod.build_surfels = _one_face_only(build, scene, motion, sim)
    try:
        with edge_rules(variant):
            result = estimate_from_frames(frames)
    finally:
        refine_mod._finish, refine_mod.sandwich, refine_mod.patches = finish, sandwich, patches
        refine_mod.build_surfels = build
    e = errors(result, motion)
    # The call whose covariance the result reports (the validation's subset fit is another).
    reported = np.radians(result.uncertainty.spin_rate_deg_s)
    call = min(calls, key=lambda k: abs(np.sqrt(k["cov"][k["free"].index(2), k["free"].index(2)]) - reported))
    bound = against_bound(motion, scene, sim, result.reference_time_s, e)["bound"]
    return {"shape": name, "distance_m": distance_m, "seed": seed, "errors": e, "bound": bound, "fit": call,
            "warnings": result.warnings,
            "points_share": (result.fit.points_used or 0) / result.fit.observations}  # fmt: skip


# --- covariance variants -------------------------------------------------------------------


def _parts(f: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Scores, Cauchy-Hessian terms per residual (as rows J_i * h_i), and the cluster of each."""
    J, r, var, c = f["J"], f["r"], f["var"], f["c"]
    e = r / np.sqrt(var)
    psi = e / (1.0 + (e / c) ** 2)
    score = J * (psi / np.sqrt(var))[:, None]
    curv = covariance_mod.cauchy_curvature(e, c) / var
    return score, curv, J, f["cluster"]


def _cluster_sums(score: np.ndarray, curv: np.ndarray, J: np.ndarray, cl: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    G_n = int(cl.max()) + 1
    G = np.zeros((G_n, J.shape[1]))
    A_c = np.zeros((G_n, J.shape[1], J.shape[1]))
    for k in range(G_n):
        i = cl == k
        G[k] = score[i].sum(axis=0)
        A_c[k] = J[i].T @ (J[i] * curv[i, None])
    return G, A_c


def cov_cr1(f: dict[str, Any]) -> np.ndarray:
    """Plain clustered sandwich with the G/(G-1) factor (CR1)."""
    score, curv, J, cl = _parts(f)
    G, A_c = _cluster_sums(score, curv, J, cl)
    Ainv = np.linalg.pinv(A_c.sum(axis=0), rcond=1e-12)
    n = len(G)
    return np.asarray(Ainv @ (G.T @ G) @ Ainv * n / (n - 1))


def cov_cr2(f: dict[str, Any]) -> np.ndarray:
    """Bell-McCaffrey CR2 for an M-estimator: G_c scaled by (I - H_cc)^-1/2 with
    H_cc = A_c A^-1 (the cluster's leverage)."""
    score, curv, J, cl = _parts(f)
    G, A_c = _cluster_sums(score, curv, J, cl)
    A = A_c.sum(axis=0)
    Ainv = np.linalg.pinv(A, rcond=1e-12)
    # Symmetric form: with L = A^-1/2, H~_c = L A_c L; adjusted score L (I - H~_c)^-1/2 L^-1 ... in
    # parameter space: u_c = A^1/2 (I - A^-1/2 A_c A^-1/2)^-1/2 A^-1/2 G_c.
    w, V = np.linalg.eigh(A)
    Ah = V @ np.diag(np.sqrt(w)) @ V.T
    Amh = V @ np.diag(1 / np.sqrt(w)) @ V.T
    B = np.zeros_like(A)
    for k in range(len(G)):
        Hk = Amh @ A_c[k] @ Amh
        hw, hV = np.linalg.eigh(np.eye(len(A)) - Hk)
        M = hV @ np.diag(1 / np.sqrt(np.clip(hw, 1e-6, None))) @ hV.T
        u = Ah @ M @ Amh @ G[k]
        B += np.outer(u, u)
    return np.asarray(Ainv @ B @ Ainv)


def cov_cr3(f: dict[str, Any]) -> np.ndarray:
    """The cluster jackknife alone (covariance.sandwich before its pooled design floor)."""
    floor = covariance_mod.pooled_design_floor
    covariance_mod.pooled_design_floor = lambda clustered, independent: clustered
    try:
        return np.asarray(covariance_mod.sandwich(f["J"], f["r"], f["var"], f["c"], f["cluster"], f["gauge"]))
    finally:
        covariance_mod.pooled_design_floor = floor


def cov_now(f: dict[str, Any]) -> np.ndarray:
    """covariance.sandwich as it is (the jackknife with the pooled design floor)."""
    return np.asarray(covariance_mod.sandwich(f["J"], f["r"], f["var"], f["c"], f["cluster"], f["gauge"]))


def cov_iid(f: dict[str, Any]) -> np.ndarray:
    """The sandwich of independent residuals (no clustering)."""
    score, curv, J, _ = _parts(f)
    Ainv = np.linalg.pinv(J.T @ (J * curv[:, None]), rcond=1e-12)
    return np.asarray(Ainv @ (score.T @ score) @ Ainv)


def floored(
    rule: Callable[[dict[str, Any]], np.ndarray], stat: str = "median"
) -> Callable[[dict[str, Any]], np.ndarray]:
    """``rule``'s covariance with each free parameter's variance raised to at least the pooled
    design effect (``stat`` over the parameters of clustered / independent variance) times its
    independent-residual variance: a parameter whose few patches happen to agree keeps the
    other parameters' design effect, not a jackknife of a few degrees of freedom."""

    def run(f: dict[str, Any]) -> np.ndarray:
        C, M = rule(f), cov_iid(f)
        ratio = np.diag(C) / np.diag(M)
        if stat == "rao-scott":
            # The mean eigenvalue of the design-effect matrix M^-1 C (Rao & Scott's first-order
            # correction), invariant to how the parameters are scaled or rotated.
            deff = float(np.trace(np.linalg.solve(M, C)) / len(M))
        else:
            deff = float(np.median(ratio) if stat == "median" else np.exp(np.mean(np.log(ratio))))
        d = np.sqrt(np.maximum(1.0, deff / ratio))
        return np.asarray(C * np.outer(d, d))

    return run


def with_patches(
    rule: Callable[[dict[str, Any]], np.ndarray], fraction: float
) -> Callable[[dict[str, Any]], np.ndarray]:
    """``rule`` with patches of ``fraction`` x today's side."""

    def run(f: dict[str, Any]) -> np.ndarray:
        g = dict(f, cluster=covariance_mod.patches(f["anchor"], f["patch_m"] * fraction))
        return rule(g)

    return run


def n_clusters(f: dict[str, Any]) -> int:
    return int(f["cluster"].max()) + 1


def effective_clusters(f: dict[str, Any], param: int) -> float:
    """Clusters weighted by their share of the information on one free parameter (Kish-style:
    (sum w)^2 / sum w^2 with w the cluster's squared jackknife shift): how many patches carry
    that parameter's variance."""
    score, curv, J, cl = _parts(f)
    G, A_c = _cluster_sums(score, curv, J, cl)
    A = A_c.sum(axis=0)
    D = np.stack([np.linalg.pinv(A - A_c[k], rcond=1e-12) @ G[k] for k in range(len(G))])
    w = D[:, param] ** 2
    return float(w.sum() ** 2 / max((w**2).sum(), 1e-300))


RULES: dict[str, Callable[[dict[str, Any]], np.ndarray]] = {
    "CR3": cov_cr3,
    "sandwich now": cov_now,
    "CR1": cov_cr1,
    "CR2": cov_cr2,
    "CR3 floor median": floored(cov_cr3),
    "CR3 floor geomean": floored(cov_cr3, "geomean"),
    "CR3 floor rao-scott": floored(cov_cr3, "rao-scott"),
    "CR3 patches/1.5": with_patches(cov_cr3, 1 / 1.5),
    "CR3 patches x2": with_patches(cov_cr3, 2.0),
}


def variants(paths: list[Path]) -> None:
    cases = [pickle.loads(p.read_bytes()) for p in paths]
    rows = []
    for c in cases:
        f = c["fit"]
        e = c["errors"]
        row: list[object] = [c["shape"], f"{c['distance_m']:g}", c["seed"], n_clusters(f)]
        for rule in RULES.values():
            s = sigmas(f["x_raw"], rule(f), f["free"])
            ratios = {p: e[f"{p}_{UNITS[p]}"] / s[p] for p in PARAMS if np.isfinite(e[f"{p}_{UNITS[p]}"])}
            worst = max(ratios, key=lambda p: ratios[p])
            sb = np.nanmedian([s[p] / c["bound"][f"{p}_{UNITS[p]}"] for p in PARAMS if p in ratios])
            row.append(f"{ratios[worst]:.2f} {worst[:1]}{worst.split('_')[1][:1]} /{sb:.1f}")
        rows.append(row)
    print(table(rows, ["shape", "m", "seed", "patches", *RULES]))
    print("cells: worst |error|/sigma, its parameter (sa spin axis, sr, pa, pr) / median sigma over bound")
    for k, label in enumerate(RULES):
        worst_all = np.array([float(str(r[4 + k]).split()[0]) for r in rows])
        sb_all = np.array([float(str(r[4 + k]).split("/")[-1]) for r in rows])
        print(f"{label:>18}: over 3 sigma {int((worst_all > 3).sum())} of {len(rows)}, max {worst_all.max():.2f}, "
              f"median sigma/bound {np.median(sb_all):.2f}")  # fmt: skip


def compare(tags: list[str]) -> None:
    """Per case of the captures of each tag: the worst |error| / reported sigma and the median
    over the four parameters of sigma / bound; per shape and range, the count over 3 sigma and
    the median sigma / bound."""
    runs = {t: {(c["shape"], c["distance_m"], c["seed"]): c for c in map(pickle.loads, (
        p.read_bytes() for p in out_dir().glob(f"sigma_capture_{t}_*.pkl")))} for t in tags}  # fmt: skip
    keys = sorted(set.intersection(*(set(r) for r in runs.values())))

    def worst(c: dict[str, Any]) -> tuple[float, str]:
        e = c["errors"]
        ratios = {p: e[f"{p}_sigma"] for p in PARAMS if np.isfinite(e[f"{p}_sigma"])}
        p = max(ratios, key=lambda k: ratios[k])
        return ratios[p], p

    def sb(c: dict[str, Any]) -> float:
        e, b = c["errors"], c["bound"]
        return float(np.nanmedian([e[f"{p}_sd"] / b[f"{p}_{UNITS[p]}"] for p in PARAMS]))

    rows = []
    for k in keys:
        cells: list[object] = [k[0], f"{k[1]:g}", k[2]]
        for t in tags:
            w, p = worst(runs[t][k])
            cells.append(f"{w:.2f} {p.split('_')[0][0]}{p.split('_')[1][0]} / {sb(runs[t][k]):.2f}")
        rows.append(cells)
    print(table(rows, ["shape", "m", "seed", *tags]))
    print("cells: worst |error|/sigma, its parameter (sa, sr, pa, pr) / median sigma over bound")

    def within(c: dict[str, Any]) -> bool:
        e, b = c["errors"], c["bound"]
        return all(not e[f"{p}_{UNITS[p]}"] > max(FLOOR[UNITS[p]], 3 * b[f"{p}_{UNITS[p]}"]) for p in PARAMS)

    def points(cs: list[dict[str, Any]]) -> str:
        shares = [c["points_share"] for c in cs if "points_share" in c]
        return f"{100 * min(shares):.1f}" if len(shares) == len(cs) else "-"

    groups = sorted({(k[0], k[1]) for k in keys})
    rows = []
    for g in groups:
        ks = [k for k in keys if k[:2] == g]
        cells = [g[0], f"{g[1]:g}", len(ks)]
        for t in tags:
            ws = [worst(runs[t][k])[0] for k in ks]
            inside = sum(within(runs[t][k]) for k in ks)
            median_sb = np.median([sb(runs[t][k]) for k in ks])
            least = points([runs[t][k] for k in ks])
            cells.append(f"{sum(w > 3 for w in ws)} / max {max(ws):.2f} / {median_sb:.2f} / {inside} / {least}")
        rows.append(cells)
    print(table(rows, ["shape", "m", "cases", *[f"{t}: over 3 / max / sigma:bound / within / points %" for t in tags]]))
    print("within: cases with every error within max(0.01 deg/s or 0.02 deg, 3 x bound); points: the least share used")


# --- noise draws from the truth -----------------------------------------------------------


def draws(name: str, distance_m: float, seed: int, size: int, n_draws: int, variant: str = "") -> None:
    """Refined from the truth on ``n_draws`` noise draws and noise-free (see the docstring).
    variant: ``no-handover`` (no point handed across cells, ``handover.assign_to_faces``),
    ``no-curvature`` (anchors at the centroids, ``surfels.CURVATURE_CORRECTION``) or
    ``oracle-one-face`` (:func:`_one_face_only`): what the fit uses, to find where a bias comes
    from."""
    motion = random_motion(np.random.default_rng(seed), distance_m=distance_m)
    rows = []
    for k in [*range(n_draws), -1]:
        scene = Scene(scanner=Scanner(lines=size, pixels=size), shape=shape_named(name), noise=k >= 0)
        sim = simulate_frames(motion, scene, seed=seed + 1000 * max(k, 0))
        T = float(sim.t_s.min())
        noise = scene.scanner.noise
        data = dense_data(sim, T, noise.range_sigma_m)
        x_true = canonical_params(motion.at_reference(T).params())
        rec: dict[str, Any] = {}
        patches = refine_mod.patches

        def patches_rec(anchor: np.ndarray, size_m: float, _rec: dict[str, Any] = rec, _p: Any = patches) -> Any:
            out = _p(anchor, size_m)
            _rec["n"] = int(out.max()) + 1
            return out

        refine_mod.patches = patches_rec  # type: ignore[assignment]
        handover, curvature = surfels_mod.assign_to_faces, surfels_mod.CURVATURE_CORRECTION
        build = refine_mod.build_surfels
        if variant == "oracle-one-face":
            refine_mod.build_surfels = _one_face_only(build, scene, motion, sim)
        if variant == "no-handover":
            surfels_mod.assign_to_faces = lambda *a, _cell=data.cell: _cell
        if variant == "no-curvature":
            surfels_mod.CURVATURE_CORRECTION = False
        try:
            with edge_rules(variant):
                fit = refine_mod.refine_dense(data, x_true, noise=noise)
        finally:
            refine_mod.patches = patches
            surfels_mod.assign_to_faces, surfels_mod.CURVATURE_CORRECTION = handover, curvature
            refine_mod.build_surfels = build
        x = fit.x
        s = motion_sigmas_deg(x, fit.cov)
        cells: list[object] = ["noise-free" if k < 0 else seed + 1000 * k, rec.get("n", 0), f"{fit.scale:.2f}"]
        for p, (a, b) in (("spin_axis", (0, 1)), ("precession_axis", (3, 4))):
            Jl = axis_tangents(x[a], x[b])
            C = Jl @ fit.cov[np.ix_([a, b], [a, b])] @ Jl.T
            w, V = np.linalg.eigh(C)
            weak = V[:, -1]
            weak = weak * np.sign(weak[np.argmax(np.abs(weak))])
            lt, lf = axis_from_angles(x_true[a], x_true[b]), axis_from_angles(x[a], x[b])
            lf = lf * np.sign(lf @ lt)
            d = lf - lt
            err = np.degrees(np.linalg.norm(d))
            cells.append(f"{np.degrees(d @ weak):+.4f} ({err:.4f}) / {s[p]:.4f} [{np.degrees(np.sqrt(w[-1])):.4f}]")
        for p, i in (("spin_rate", 2), ("precession_rate", 5)):
            cells.append(f"{np.degrees(x[i] - x_true[i]):+.4f} / {s[p]:.4f}")
        rows.append([cells[0], cells[1], cells[2], cells[3], cells[5], cells[4], cells[6]])
        print(f"  draw {cells[0]} done", flush=True)
    print(f"\n{name} {distance_m:g} m motion {seed}, refined from the truth {variant}")
    print(table(rows, ["noise seed", "patches", "scale", "spin axis", "spin rate", "prec axis", "prec rate"]))
    print("axes: signed error along the weakest direction (total angle) / sigma [weakest-direction sigma];"
          " rates: signed error / sigma")  # fmt: skip


def _one_face_only(build: Any, scene: Scene, motion: Any, sim: Any) -> Any:
    """``build_surfels`` with every surfel whose points lie on two or more mesh faces (by the
    simulator's truth) made non-planar: what the fit would give if no edge's points entered a
    surfel (an oracle, for the size of that effect only)."""
    from dataclasses import replace

    from scipy.spatial import cKDTree

    from .dense_bound import face_of_hits

    face_all = face_of_hits(scene, motion, sim.reference_m)[0]
    tree = cKDTree(sim.xyz_m)
    faces_of: dict[int, tuple[Any, np.ndarray]] = {}  # the estimate's data (and its subsets) by id

    def run(data: Any, *a: Any, **k: Any) -> Any:
        surf = build(data, *a, **k)
        if id(data) not in faces_of:
            # The estimate's points are the simulator's, reordered (and a subset for the check).
            faces_of[id(data)] = (data, face_all[tree.query(data.xyz_m, workers=-1)[1]])
        face = faces_of[id(data)][1]
        m = len(surf.count)
        lo = np.full(m, np.iinfo(np.int64).max)
        hi = np.full(m, -2)
        np.minimum.at(lo, surf.point_cell, face)
        np.maximum.at(hi, surf.point_cell, face)
        return replace(surf, planar=surf.planar & (lo == hi) & (lo >= 0))

    return run


def _eroded(surf: Any, data: Any, *, border_only: bool) -> Any:
    """``surf`` with the planar cells beside a non-planar one (any of the 4 side neighbours in
    the view; ``border_only``: beside a cell that is missing or not interior, a silhouette or
    occlusion border) made non-planar: candidate rules against edge-straddling surfels."""
    from dataclasses import replace

    from tumblescan.linescan.dense.faces import SIDE_NEIGHBOURS

    nb = data.neighbours[:, list(SIDE_NEIGHBOURS)]
    safe = np.maximum(nb, 0)
    beside = (nb < 0) | ~data.interior[safe] if border_only else (nb < 0) | ~surf.planar[safe]
    kept = surf.planar & ~beside.any(axis=1)
    print(f"  {variant_name(border_only)}: planar cells {int(surf.planar.sum())} -> {int(kept.sum())}")
    return replace(surf, planar=kept)


def variant_name(border_only: bool) -> str:
    return "erode-border" if border_only else "erode"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("mode", choices=["capture", "draws", "variants", "attribute", "compare"])
    parser.add_argument("paths", nargs="*", type=Path)
    parser.add_argument("--shapes", nargs="+", default=["octagon-truss"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    parser.add_argument("--distances", nargs="+", type=float, default=[50.0])
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--draws", type=int, default=8)
    parser.add_argument("--tag", default="before")
    parser.add_argument("--tags", nargs="+", default=["before", "after"], help="compare: the captures' tags")
    variants_ = ["", "no-handover", "no-curvature", "oracle-one-face", "no-beside", "erode", "erode-border",
                 "no-edge-rules"]  # fmt: skip
    parser.add_argument("--variant", default="", choices=variants_, help="draws, capture, attribute: see each")
    args = parser.parse_args()
    if args.mode == "variants":
        variants(args.paths)
        return
    if args.mode == "compare":
        compare(args.tags)
        return
    for name in args.shapes:
        for d in args.distances:
            for s in args.seeds:
                if args.mode == "attribute":
                    attribute(name, d, s, args.size, noisy=False, variant=args.variant)
                    attribute(name, d, s, args.size, noisy=True, variant=args.variant)
                    continue
                if args.mode == "draws":
                    draws(name, d, s, args.size, args.draws, args.variant)
                    continue
                c = capture(name, d, s, args.size, args.variant)
                path = out_dir() / f"sigma_capture_{args.tag}_{name}_{d:g}_{s}.pkl"
                path.write_bytes(pickle.dumps(c))
                e = c["errors"]
                worst = max(e[f"{p}_sigma"] for p in PARAMS if np.isfinite(e[f"{p}_sigma"]))
                n = n_clusters(c["fit"])
                print(f"{name} {d:g} m seed {s}: worst {worst:.2f} sigma, patches {n} -> {path.name}", flush=True)


# --- where a noise-free bias comes from -----------------------------------------------------


def attribute(name: str, distance_m: float, seed: int, size: int, noisy: bool, variant: str = "") -> None:
    """At the true motion: the last stage's residuals, and the one least-squares step they make
    (``A^-1 J^T W r``, the bias to first order on noise-free frames), split by what the source
    surfel's points hit on the mesh (which build calls of the parametric shape)."""
    from .curved_diag import part_of_hits, part_of_triangles
    from .dense_bound import last_stage_matches

    motion = random_motion(np.random.default_rng(seed), distance_m=distance_m)
    scene = Scene(scanner=Scanner(lines=size, pixels=size), shape=shape_named(name), noise=noisy)
    sim, data, mapping = frames_at_truth(motion, scene, seed)
    x_true, noise = mapping.x, scene.scanner.noise
    beside = surfels_mod.beside_face
    if variant == "no-beside":
        surfels_mod.beside_face = lambda planes, candidate, face: np.zeros_like(candidate)
    try:
        surf = surfels_mod.build_surfels(data, mapping, noise)
    finally:
        surfels_mod.beside_face = beside
    if variant in ("erode", "erode-border"):
        surf = _eroded(surf, data, border_only=variant == "erode-border")
    names, tri_part = part_of_triangles(scene.shape)
    part = part_of_hits(scene, motion, sim, tri_part)
    kind = np.array([n.split(":")[1] for n in names])
    kept = np.arange(len(sim.xyz_m)) if data.kept is None else np.flatnonzero(data.kept)
    point_kind = np.where(part[kept] >= 0, kind[np.maximum(part[kept], 0)], "none")
    m_cells = len(surf.count)
    kinds = sorted(set(point_kind))
    share = np.stack([np.bincount(surf.point_cell, point_kind == k, minlength=m_cells) for k in kinds], axis=1)
    share = share / np.maximum(share.sum(axis=1, keepdims=True), 1)
    mt, lin = last_stage_matches(data, mapping, surf, noise)
    w = 1.0 / lin.var
    A = lin.J.T @ (lin.J * w[:, None])
    Ainv = np.linalg.inv(A)
    sign = np.sign(x_true[[2, 5]])
    src_share = share[mt.src]
    dst_share = share[mt.dst]
    major = np.array(kinds)[np.argmax(src_share, axis=1)]
    pure = (src_share.max(axis=1) > 0.999) & (dst_share.max(axis=1) > 0.999)
    # One mesh face (coplanar triangles) for every point of both surfels, or not: a cell
    # straddling a plate's edge or the bus's corner is "pure" by part but not by face.
    from .dense_bound import face_of_hits

    face = face_of_hits(scene, motion, sim.reference_m)[0][kept]
    n_faces = int(face.max()) + 2
    lo = np.full(m_cells, n_faces)
    hi = np.full(m_cells, -2)
    np.minimum.at(lo, surf.point_cell, face)
    np.maximum.at(hi, surf.point_cell, face)
    one_face = (lo == hi) & (lo >= 0)
    same = one_face[mt.src] & one_face[mt.dst] & (lo[mt.src] == lo[mt.dst])
    classes = {f"{k}, one face": pure & same & (major == k) for k in kinds}
    straddle = ~one_face[mt.src] | ~one_face[mt.dst]
    for k in kinds:
        classes[f"{k}, a surfel on 2+ faces"] = pure & ~same & straddle & (major == k)
        classes[f"{k}, pair across faces"] = pure & ~same & ~straddle & (major == k)
        classes[f"mixed, mostly {k}"] = ~pure & (major == k)
    e = lin.r / np.sqrt(lin.var)
    rows = []
    total = Ainv @ (lin.J.T @ (w * lin.r))
    for label, sel in [*classes.items(), ("all", np.ones(len(e), dtype=bool))]:
        if not sel.any():
            continue
        dx = Ainv @ (lin.J[sel].T @ (w[sel] * lin.r[sel]))
        rows.append([label, int(sel.sum()), len(np.unique(mt.src[sel])), f"{np.mean(e[sel]):+.2f}",
                     f"{np.sqrt(np.mean(e[sel] ** 2)):.2f}",
                     f"{np.degrees(dx[2] * sign[0]):+.5f}", f"{np.degrees(dx[5] * sign[1]):+.5f}"])  # fmt: skip
    print(f"\n{name} {distance_m:g} m seed {seed}, {'noisy' if noisy else 'noise-free'}, at the truth: kinds {kinds}")
    header = ["residuals' sources", "residuals", "surfels", "mean z", "rms z", "step spin rate", "step prec rate"]
    print(table(rows, header))
    print(f"(one LS step from the truth, all: spin rate {np.degrees(total[2] * sign[0]):+.5f}, "
          f"prec rate {np.degrees(total[5] * sign[1]):+.5f} deg/s)")  # fmt: skip


if __name__ == "__main__":
    main()
