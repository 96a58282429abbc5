"""Every hit against a plane of the map, at the truth: what per-point residuals would give.

    python -m bench.linescan.patch_potential [--shapes box long-array] [--distances 50 100]
                                             [--seeds 0 1 2 3 4] [--voxel 6] [--iterations 4]
                                             [--size 512] [--stem patch_potential]

The dense fit matches surfel centroids (:mod:`~tumblescan.linescan.dense.matching`); point-to-plane
registration against a map (CT-ICP, KISS-ICP) and plane factors (BALM) take every point instead,
each with its own noise, and could use the hits the surfels leave out. This bench measures that
design at the true motion (the real-shapes bench's seeded motion and frames, ``T`` the first hit's
time): the hits at ``T`` cut into *patches* (cubes ``--voxel`` surfel sizes wide, split by the
direction of the planar cells' normals among 26), each a plane with 3 nuisance parameters, and
every hit ``i`` of a patch ``k`` gives

    r_i = n_k . (M(x_i; x) - c_k) - (p_k0 + p_k1 u_i + p_k2 v_i),
    var r_i = n_obs^T Sigma_i n_obs = s_r^2 (n_obs . s)^2 + (s_a rho)^2 (1 - (n_obs . s)^2),

``(u, v)`` the hit's offsets along the patch's in-plane axes at ``T``, ``n_obs`` the normal in the
hit's sensor frame, ``s`` its line of sight, ``Sigma_i`` the sensor's noise (``SensorNoise``). The
patches' parameters are profiled out (variable projection) and the Cauchy cost's optimum from the
truth is found by Gauss-Newton steps, its error over the dense bound (``dense_bound.py``) beside
the surfel pairs' (``loss_choice.py``'s Cauchy column).

The sensor's noise is not isotropic (2 cm along the sight against ``s_a rho`` = 0.9 cm across it
at 50 m, 1.7 cm at 100 m), so a hit's noise along the normal is correlated with its noise along
the plane, and two errors-in-variables biases follow, each summed over a million hits:

- the motion's Jacobian ``J_i`` is taken at the noisy hit, and ``E[r_i J_i] = d(var r_i)/dx / 2``
  (the normal turned towards the sensor's less noisy directions lowers the cost). Corrected
  (``eiv``) by the gradient of ``sum rho(r_i^2 / var_i(x))``, whose ``var_i`` turns with ``x``;
- the patch's tilt is regressed on noisy ``(u, v)``, whose noise is correlated with ``r``'s.
  Corrected by corrected least squares: the noise's moments ``E[(u, v) (u, v)^T]`` and ``E[(u,
  v) r]`` (from ``Sigma_i``) taken out of the normal equations.

A surfel's centroid averages its points' noise before any product is formed, so the fit's pairs
carry these biases divided by the points per surfel (measured: 0.0-0.05 bounds; the surfels'
normals are already taken from the scatter less the noise's covariance).

Designs: ``planar cells`` (the hits of the planar surfels only, the fit's points), raw and
corrected; ``all hits`` (every hit within ``GATE_SIGMAS`` of a plane of its cube joins it),
corrected; and the same with the true faces (an oracle: a patch keeps only the hits of its
majority face of the mesh, so the hits of the neighbour face that lie near its plane along an
edge are out). Prints per case and shape the RMS over the cases and the four parameters of the
error over the bound, and of the design's own sigma over it; writes
``bench/out/patch_potential.json`` and a plot.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from tumblescan.linescan.dense.data import DenseData
from tumblescan.linescan.dense.mapping import LineMapping
from tumblescan.linescan.dense.matching import CAUCHY_C, cauchyweights, robust_sigma
from tumblescan.linescan.dense.surfels import Surfels, normal_variance
from tumblescan.linescan.sensor import SensorNoise, perpendiculars

from ..common import grouped_bars, machine, out_dir, saved_figure, table
from .dense_bound import (
    face_of_hits,
    last_stage_matches,
    majority_face,
)
from .loss_choice import cauchy, newton_step, normalised, over_bound, truth_case

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

# A hit outside the planar surfels joins the plane of its cube it lies on within this many sigmas.
GATE_SIGMAS = 3.0
# A patch with fewer hits is left out (its plane would take most of what they say).
MIN_PATCH_POINTS = 30
# Cauchy reweighting passes of the planes at each motion, before the motion's step.
PLANE_PASSES = 3
_DIRECTIONS = np.array(
    [(a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1) if (a, b, c) != (0, 0, 0)], dtype=float
)
DIRECTIONS = _DIRECTIONS / np.linalg.norm(_DIRECTIONS, axis=1)[:, None]


def noise_times(noise: SensorNoise, xyz_obs: FloatArray, b: FloatArray) -> FloatArray:
    """``Sigma_i b_i`` per row ``(n, 3)`` (m^2), ``Sigma_i = (s_a rho)^2 I + (s_r^2 - (s_a rho)^2) s s^T``
    the noise of the hit ``xyz_obs`` (sensor frame, m) with line of sight ``s``; ``b`` ``(n, 3)`` in
    the sensor frame."""
    rho = np.linalg.norm(xyz_obs, axis=1)
    s = xyz_obs / rho[:, None]
    across = (noise.angle_sigma_rad * rho) ** 2
    along = (noise.range_sigma_m**2 - across) * np.einsum("ni,ni->n", s, b)
    return np.asarray(across[:, None] * b + along[:, None] * s)


def noise_product(noise: SensorNoise, xyz_obs: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    """``a_i^T Sigma_i b_i`` per row (m^2): :func:`noise_times` seen along ``a`` ``(n, 3)``."""
    return np.asarray(np.einsum("ni,ni->n", a, noise_times(noise, xyz_obs, b)))


def plane_fit(
    w: FloatArray,
    uv: FloatArray,
    weight: FloatArray,
    patch: IntArray,
    n_patches: int,
    noise_moments: tuple[FloatArray, FloatArray] | None,
) -> tuple[FloatArray, FloatArray]:
    """Each patch's plane ``w = p0 + p1 u + p2 v`` by weighted least squares: ``(K, 3)`` parameters
    and the ``(K, 3, 3)`` normal matrices ``sum weight a a^T`` (``a = (1, u, v)``).

    w: ``(n,)`` heights along the patch normal (m); uv: ``(n, 2)`` in-plane offsets (m); weight:
    ``(n,)`` (1/m^2); patch: ``(n,)`` in ``[0, n_patches)``. noise_moments: the noise's
    ``E[d(u,v) d(u,v)^T]`` ``(n, 2, 2)`` and ``E[d(u,v) dw]`` ``(n, 2)`` (m^2), taken out of the normal
    equations (corrected least squares: the tilt unbiased when ``(u, v)`` and ``w`` share noise);
    the returned matrices are the raw ones, the Jacobian's."""
    a = np.column_stack([np.ones(len(w)), uv])
    raw = np.zeros((n_patches, 3, 3))
    rhs = np.zeros((n_patches, 3))
    for j in range(3):
        rhs[:, j] = np.bincount(patch, weight * a[:, j] * w, minlength=n_patches)
        for k in range(3):
            raw[:, j, k] = np.bincount(patch, weight * a[:, j] * a[:, k], minlength=n_patches)
    normal = raw.copy()
    if noise_moments is not None:
        cov_uv, cov_uv_w = noise_moments
        for j in range(2):
            rhs[:, j + 1] -= np.bincount(patch, weight * cov_uv_w[:, j], minlength=n_patches)
            for k in range(2):
                normal[:, j + 1, k + 1] -= np.bincount(patch, weight * cov_uv[:, j, k], minlength=n_patches)
    # A patch left without hits gets the identity: its plane is zero and enters nothing.
    trace = np.trace(raw, axis1=1, axis2=2)
    ridge = np.where(trace > 0, 1e-12 * trace, 1.0)[:, None, None] * np.eye(3)
    return np.asarray(np.linalg.solve(normal + ridge, rhs[:, :, None])[:, :, 0], dtype=float), raw + ridge


@dataclass(frozen=True)
class Patches:
    """The hits' patches at ``T``: ``patch`` ``(n,)`` (-1: none), and each patch's centre, normal
    and in-plane axes ``(K, 3)``."""

    patch: IntArray
    centre: FloatArray
    normal: FloatArray
    e1: FloatArray
    e2: FloatArray

    @property
    def used(self) -> BoolArray:
        return np.asarray(self.patch >= 0)


def cut_patches(xyz_T: FloatArray, cell_normal_T: FloatArray, planar: BoolArray, voxel_m: float) -> Patches:
    """Patches of the planar hits: cubes ``voxel_m`` wide at ``T``, split by the nearest of 26
    directions to the hit's cell's normal (two faces of an edge fall apart). xyz_T, cell_normal_T:
    ``(n, 3)``; planar: ``(n,)`` the hits of planar surfels."""
    direction = np.argmax(cell_normal_T @ DIRECTIONS.T, axis=1)
    key = cube_keys(xyz_T, voxel_m) * 32 + direction
    keys, inverse = np.unique(key[planar], return_inverse=True)
    patch = np.full(len(xyz_T), -1, dtype=np.int64)
    patch[planar] = inverse
    centre = np.zeros((len(keys), 3))
    normal = np.zeros((len(keys), 3))
    np.add.at(centre, inverse, xyz_T[planar])
    np.add.at(normal, inverse, cell_normal_T[planar])
    centre /= np.bincount(inverse, minlength=len(keys))[:, None]
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    e1, e2 = perpendiculars(normal)
    return Patches(patch, centre, normal, e1, e2)


@dataclass(frozen=True)
class Hits:
    """The used hits at one motion: heights ``w`` ``(n,)`` along their patches' normals and
    in-plane offsets ``uv`` ``(n, 2)`` (m), their patches ``k``, variances along the normal
    ``var`` (m^2), and the noise's moments for the corrected plane fit (or None)."""

    w: FloatArray
    uv: FloatArray
    k: IntArray
    var: FloatArray
    moments: tuple[FloatArray, FloatArray] | None


class PatchFit:
    """The patches' Cauchy cost at a motion with its planes fitted, and steps of its estimating
    equation (the Gauss-Newton step of the profiled cost when not ``corrected``)."""

    def __init__(self, data: DenseData, noise: SensorNoise, patches: Patches, *, corrected: bool) -> None:
        self.data, self.noise, self.patches, self.corrected = data, noise, patches, corrected

    def _obs(self, mapping: LineMapping, idx: IntArray, v_T: FloatArray) -> FloatArray:
        """``v_T`` ``(n, 3)`` at ``T`` in each hit's sensor frame (``R v = (R^T)^T v``)."""
        return np.einsum("nij,ni->nj", mapping.Rt[self.data.line[idx]], v_T)

    def hits(self, mapping: LineMapping, idx: IntArray) -> Hits:
        """The hits ``idx`` at ``mapping``: everything their planes' fits and steps share."""
        pt, xyz = self.patches, self.data.xyz_m[idx]
        k = pt.patch[idx]
        d = mapping.apply(xyz, self.data.line[idx]) - pt.centre[k]
        uv = np.column_stack([np.einsum("ni,ni->n", d, pt.e1[k]), np.einsum("ni,ni->n", d, pt.e2[k])])
        n_obs = self._obs(mapping, idx, pt.normal[k])
        moments = None
        if self.corrected:
            e1, e2 = self._obs(mapping, idx, pt.e1[k]), self._obs(mapping, idx, pt.e2[k])
            cov_uv = np.empty((len(idx), 2, 2))
            cov_uv[:, 0, 0] = noise_product(self.noise, xyz, e1, e1)
            cov_uv[:, 1, 1] = noise_product(self.noise, xyz, e2, e2)
            cov_uv[:, 0, 1] = cov_uv[:, 1, 0] = noise_product(self.noise, xyz, e1, e2)
            cov_uv_w = np.column_stack(
                [noise_product(self.noise, xyz, e1, n_obs), noise_product(self.noise, xyz, e2, n_obs)]
            )
            moments = (cov_uv, cov_uv_w)
        w = np.einsum("ni,ni->n", d, pt.normal[k])
        return Hits(w, uv, k, normal_variance(self.noise, xyz, n_obs), moments)

    def planes(self, hits: Hits, weight: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The planes fitted with the extra weights ``weight`` ``(n,)``: the hits' residuals (m),
        the planes ``(K, 3)`` and their normal matrices ``(K, 3, 3)``."""
        plane, normal_matrix = plane_fit(
            hits.w, hits.uv, weight / hits.var, hits.k, len(self.patches.centre), hits.moments
        )
        k = hits.k
        r = hits.w - plane[k, 0] - plane[k, 1] * hits.uv[:, 0] - plane[k, 2] * hits.uv[:, 1]
        return r, plane, normal_matrix

    def step(self, x: FloatArray) -> tuple[FloatArray, FloatArray, float]:
        """One step from ``x`` ``(9,)``: the step, the reweighted Gauss-Newton matrix ``(9, 9)``
        of the profiled cost (its inverse times ``s^2`` is the design's covariance, about 4 %
        above the Cauchy optimum's) and the residuals' robust scale ``s``."""
        data, pt = self.data, self.patches
        mapping = LineMapping(x, data.tau_s, tuple(range(9)))
        idx = np.flatnonzero(pt.used)
        hits = self.hits(mapping, idx)
        robust = np.ones(len(idx))
        for _ in range(PLANE_PASSES):
            r, _, _ = self.planes(hits, robust)
            e = r / np.sqrt(hits.var)
            scale = max(robust_sigma(e), 1e-12)
            robust = cauchyweights(e, scale)
        r, plane, normal_matrix = self.planes(hits, robust)
        k = hits.k
        # The plane's slope turns the normal each hit's motion is measured along.
        g = pt.normal[k] - plane[k, 1:2] * pt.e1[k] - plane[k, 2:3] * pt.e2[k]
        J = mapping.normal_derivative(g, data.xyz_m[idx], data.line[idx])
        weight = robust / hits.var
        a = np.column_stack([np.ones(len(idx)), hits.uv])
        B = np.zeros((len(pt.centre), 3, J.shape[1]))
        for j in range(3):
            for c in range(J.shape[1]):
                B[:, j, c] = np.bincount(k, weight * a[:, j] * J[:, c], minlength=len(pt.centre))
        H = (J * weight[:, None]).T @ J - np.einsum("kaj,kab,kbc->jc", B, np.linalg.inv(normal_matrix), B)
        grad = (J * weight[:, None]).T @ r
        if self.corrected:
            dv = self.variance_gradient(mapping, idx)
            grad -= 0.5 * ((weight * r * r / hits.var)[:, None] * dv).sum(axis=0)
        return -np.linalg.solve(H, grad), H, scale

    def variance_gradient(self, mapping: LineMapping, idx: IntArray) -> FloatArray:
        """``d var_i / dx`` ``(n, 9)`` of the hits ``idx``: ``var = n_obs^T Sigma n_obs`` with
        ``n_obs = R(tau; x) n`` (``n`` the patch's normal, as in the residuals' variance), so
        ``d var = 2 n^T d(R^T) (Sigma n_obs)``; the centre does not turn the normal."""
        assert mapping.free == tuple(range(9))
        n = self.patches.normal[self.patches.patch[idx]]
        sigma_n = noise_times(self.noise, self.data.xyz_m[idx], self._obs(mapping, idx, n))
        # normal_derivative contracts n^T d(R^T) (v - centre); its centre columns are dropped.
        dv = 2.0 * mapping.normal_derivative(n, sigma_n + mapping.center, self.data.line[idx])
        dv[:, 6:] = 0.0
        return dv

    def optimum(self, x0: FloatArray, iterations: int) -> tuple[FloatArray, FloatArray, float, float]:
        """Where ``iterations`` steps from ``x0`` end, the last step's matrix and scale, and the
        last step's largest component over its sigma (how far from converged)."""
        x = x0.copy()
        H, scale, last = np.eye(len(x0)), 1.0, np.inf
        for _ in range(iterations):
            dx, H, scale = self.step(x)
            x = x + dx
            last = float(np.max(np.abs(dx) / (scale * np.sqrt(np.diag(np.linalg.inv(H))))))
        return x, H, scale, last


def gate_hits(fit: PatchFit, mapping: LineMapping, xyz_T: FloatArray, cube_m: float) -> Patches:
    """Every hit outside the planar surfels given the plane of its cube it lies on within
    ``GATE_SIGMAS`` (the nearest in sigmas among those facing the hit's sensor), then the patches
    with fewer than ``MIN_PATCH_POINTS`` hits dropped. xyz_T: ``(n, 3)`` every hit at ``T`` under
    ``mapping``, as the patches were cut."""
    pt, data = fit.patches, fit.data
    idx = np.flatnonzero(pt.used)
    _, plane, _ = fit.planes(fit.hits(mapping, idx), np.ones(len(idx)))
    cube = cube_keys(xyz_T, cube_m)
    best, best_z = pt.patch.copy(), np.full(len(xyz_T), np.inf)
    others = np.flatnonzero(~pt.used)
    # Hits and patches keyed by cube: each hit is tried against every patch of its cube.
    patch_key = np.full(len(pt.centre), -1, dtype=np.int64)
    patch_key[pt.patch[idx]] = cube[idx]
    order = np.argsort(patch_key, kind="stable")
    sorted_keys = patch_key[order]
    hit_key = cube[others]
    lo, hi = np.searchsorted(sorted_keys, hit_key, "left"), np.searchsorted(sorted_keys, hit_key, "right")
    sensor_T = mapping.apply(np.zeros((len(others), 3)), data.line[others])
    for offset in range(int((hi - lo).max(initial=0))):
        ok = lo + offset < hi
        hits, k = others[ok], order[lo[ok] + offset]
        # Only planes facing the hit's sensor: the back of a plate a few centimetres thick lies
        # within the gate of a hit pushed back by its noise, and would take exactly those.
        facing = np.einsum("ni,ni->n", pt.normal[k], sensor_T[ok] - xyz_T[hits]) > 0
        hits, k = hits[facing], k[facing]
        d = xyz_T[hits] - pt.centre[k]
        u, v = np.einsum("ni,ni->n", d, pt.e1[k]), np.einsum("ni,ni->n", d, pt.e2[k])
        off = np.einsum("ni,ni->n", d, pt.normal[k]) - plane[k, 0] - plane[k, 1] * u - plane[k, 2] * v
        n_obs = fit._obs(mapping, hits, pt.normal[k])
        z = np.abs(off) / np.sqrt(normal_variance(fit.noise, data.xyz_m[hits], n_obs))
        better = z < best_z[hits]
        best[hits[better]], best_z[hits[better]] = k[better], z[better]
    joined = np.where(np.isfinite(best_z) & (best_z > GATE_SIGMAS), -1, best)
    return _drop_small(replace(pt, patch=joined))


def cube_keys(xyz_T: FloatArray, cube_m: float) -> IntArray:
    """One key per hit ``(n,)`` for its cube ``cube_m`` wide, counted from the hits' lowest corner."""
    cube = np.floor((xyz_T - xyz_T.min(axis=0)) / cube_m).astype(np.int64)
    return np.asarray((cube[:, 0] * 100_003 + cube[:, 1]) * 100_003 + cube[:, 2])


def _drop_small(pt: Patches) -> Patches:
    counts = np.bincount(pt.patch[pt.used], minlength=len(pt.centre))
    small = counts < MIN_PATCH_POINTS
    return replace(pt, patch=np.where(pt.used & small[np.maximum(pt.patch, 0)], -1, pt.patch))


def true_faces_only(pt: Patches, face: IntArray) -> Patches:
    """Each patch keeps only the hits of its majority face (``face`` ``(n,)``, -1: none)."""
    ok = pt.used & (face >= 0)
    majority = majority_face(pt.patch[ok], face[ok], len(pt.centre))
    keep = ok & (face == majority[np.maximum(pt.patch, 0)])
    return _drop_small(replace(pt, patch=np.where(keep, pt.patch, -1)))


def surfel_pairs_step(data: DenseData, mapping: LineMapping, surf: Surfels, noise: SensorNoise) -> FloatArray:
    """The fit's design: the Cauchy cost's Newton step from the truth (``loss_choice.py``'s)."""
    _, lin = last_stage_matches(data, mapping, surf, noise)
    return newton_step(*normalised(lin), cauchy(CAUCHY_C))


DESIGNS = (
    "surfel pairs",
    "planar cells, raw",
    "planar cells, corrected",
    "all hits, corrected",
    "all hits, true faces",
)


def case(name: str, distance_m: float, seed: int, size: int, voxel: float, iterations: int) -> dict[str, object]:
    """Error / bound and sigma / bound per parameter of each design on one seeded case."""
    tc = truth_case(name, distance_m, seed, size)
    motion, scene, sim, data, mapping, surf = tc.motion, tc.scene, tc.sim, tc.data, tc.mapping, tc.surf
    noise, x0, bound = scene.scanner.noise, mapping.x, tc.bound
    dx = surfel_pairs_step(data, mapping, surf, noise)
    out: dict[str, object] = {"shape": name, "distance_m": distance_m, "seed": seed}
    errors: dict[str, list[float]] = {"surfel pairs": over_bound(x0, bound, dx)}
    sigmas: dict[str, list[float]] = {}
    used: dict[str, float] = {"surfel pairs": float(np.mean(surf.planar[surf.point_cell]))}
    xyz_T = mapping.apply(data.xyz_m, data.line)
    cell_normal_T = np.einsum("nij,nj->ni", mapping.Rt[surf.line], surf.normal_obs)[surf.point_cell]
    planar = np.asarray(surf.planar[surf.point_cell])
    cube_m = voxel * data.surfel_m
    planes = _drop_small(cut_patches(xyz_T, cell_normal_T, planar, cube_m))
    every = gate_hits(PatchFit(data, noise, planes, corrected=True), mapping, xyz_T, cube_m)
    face = face_of_hits(scene, motion, sim.reference_m)[0]
    designs = {
        "planar cells, raw": (planes, False),
        "planar cells, corrected": (planes, True),
        "all hits, corrected": (every, True),
        "all hits, true faces": (true_faces_only(every, face if data.kept is None else face[data.kept]), True),
    }
    last: dict[str, float] = {}
    for label, (patches, corrected) in designs.items():
        x, H, scale, last[label] = PatchFit(data, noise, patches, corrected=corrected).optimum(x0, iterations)
        errors[label] = over_bound(x0, bound, x - x0)
        sigmas[label] = over_bound(x0, bound, np.asarray(np.linalg.inv(H), dtype=float) * scale**2)
        used[label] = float(np.mean(patches.used))
    out.update(errors=errors, sigmas=sigmas, used=used, last_step_over_sigma=last)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--shapes", nargs="+", default=["box", "long-array"])
    parser.add_argument("--distances", nargs="+", type=float, default=[50.0, 100.0])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4])
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--voxel", type=float, default=6.0, help="patch cubes' width in surfel sizes")
    parser.add_argument("--iterations", type=int, default=4)
    parser.add_argument("--stem", default="patch_potential")
    args = parser.parse_args()
    print(machine())
    cases = []
    for name in args.shapes:
        for distance in args.distances:
            for seed in args.seeds:
                c = case(name, distance, seed, args.size, args.voxel, args.iterations)
                cases.append(c)
                errors = c["errors"]
                assert isinstance(errors, dict)
                line = "  ".join(f"{k}: {' '.join(f'{v:.2f}' for v in errors[k])}" for k in DESIGNS)
                print(f"  {name} {distance:g} m seed {seed}: {line}", flush=True)
    rows = []
    summary: dict[str, dict[str, dict[str, float]]] = {}
    for name in args.shapes:
        for label in DESIGNS:
            mine = [c for c in cases if c["shape"] == name]
            entry = {f"error_over_bound_{d:g}m": _rms(mine, "errors", label, d) for d in args.distances}
            entry["error_over_bound"] = _rms(mine, "errors", label)
            entry["sigma_over_bound"] = _rms(mine, "sigmas", label) if label != "surfel pairs" else float("nan")
            entry["used"] = float(np.mean([c["used"][label] for c in mine]))  # type: ignore[index]
            summary.setdefault(name, {})[label] = entry
            sigma = "" if label == "surfel pairs" else f"{entry['sigma_over_bound']:.2f}"
            errors = [f"{entry[f'error_over_bound_{d:g}m']:.2f}" for d in args.distances]
            rows.append(
                [name, label, *errors, f"{entry['error_over_bound']:.2f}", sigma, f"{100 * entry['used']:.1f} %"]
            )
    converged = max(v for c in cases for v in c["last_step_over_sigma"].values())  # type: ignore[attr-defined]
    print("\nRMS over the cases and the four parameters, where each design's steps from the truth end:")
    header = ["shape", "design", *(f"error / bound, {d:g} m" for d in args.distances), "all", "sigma / bound"]
    print(table(rows, [*header, "hits used"]))
    print(f"the last step's largest component: {converged:.3f} of its sigma")
    out = out_dir()
    (out / f"{args.stem}.json").write_text(json.dumps({"summary": summary, "cases": cases}, indent=1))
    _plot(summary, out / f"{args.stem}.png")
    print(f"wrote {out / args.stem}.json and .png")


def _rms(cases: list[dict[str, object]], key: str, label: str, distance: float | None = None) -> float:
    """RMS over the cases (at ``distance``, or all) and the four parameters of ``case[key][label]``."""
    values = [c[key][label] for c in cases if distance is None or c["distance_m"] == distance]  # type: ignore[index]
    return float(np.sqrt(np.mean(np.square(values))))


def _plot(summary: dict[str, dict[str, dict[str, float]]], path: Path) -> None:
    shapes = list(summary)
    title = "Per-hit residuals against planes of the map, at the truth (1 = efficient)"
    with saved_figure(path, title=title, ylabel="RMS error / dense bound (bars); design's sigma (ticks)") as ax:
        at = grouped_bars(ax, shapes, {k: [summary[s][k]["error_over_bound"] for s in shapes] for k in DESIGNS})
        for label in DESIGNS:
            ax.plot(at[label], [summary[s][label]["sigma_over_bound"] for s in shapes], "k_", ms=12)
        ax.axhline(1.0, color="k", lw=0.8, ls=":")


if __name__ == "__main__":
    main()
