"""Dense continuous-time refinement of the motion from line-scan frames (beyond the paper).

Every point ``p`` seen at ``t = T + tau`` maps to the reference time as

    M(p, tau; x) = O_p + R(tau)^T (p - O_p)

and with the right motion the mapped frames coincide. For points ``p`` of frame ``a`` and
their nearest mapped neighbours ``q`` in frame ``b`` the refinement minimizes the robust
(Cauchy) sum of point-to-plane distances

    r = n_q(x) . (M(p, tau_p; x) - M(q, tau_q; x))

over the 9 motion parameters ``x``, by Gauss-Newton steps with correspondences re-found
after each step (as ICP does). ``n_q`` is the surface normal at ``q`` at its own observation
time (principal axes of its neighbours in the mapped frame, re-estimated as the motion
improves), turned to ``T`` with ``R(tau_q)^T``. Points on the same line share ``tau``, so
the rotations and their derivatives are computed once per line, not per point.

Frames are subsampled twice: targets (one point per ``target`` voxel, normals and a
planarity check) and, from those, sources (one per ``source`` voxel). The first stage pairs
each frame with the next few only (their correspondences are right even from a rough start);
the second pairs every frame with every later one, whose long time baselines fix the rates.

Covariance: the sandwich ``H^-1 (sum_c g_c g_c^T) H^-1`` with ``H = J^T W J`` and ``g_c`` the
gradient of all residuals of source point ``c`` (one point enters several pairs, so its noise
is counted once), which is the Cramer-Rao-type bound for the points used.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field
from scipy.spatial import cKDTree

from .motion import N_PARAMS, axis_from_angles, canonical_params, rotation_matrix
from .uncertainty import canonical_cov

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

ALL_FREE = tuple(range(N_PARAMS))
SPIN_ONLY_FREE = (0, 1, 2, 6, 7, 8)
STEP = 1e-20  # complex-step size: exact derivatives, no cancellation
CAUCHY_C = 2.385  # Cauchy constant for 95 % efficiency under Gaussian noise
MAX_NORMAL_ANGLE_COS = np.cos(np.radians(45.0))
MAX_CURVATURE = 0.03
# Re-estimate normals once the rotational parameters have moved this much in all (radians).
NORMAL_REFRESH_RAD = 1e-2  # smallest / summed eigenvalue of a neighbourhood: larger is an edge or a corner


class DenseConfig(BaseModel):
    """Sampling and iteration settings of the dense refinement (lengths in metres)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    target_voxel_m: float | None = Field(None, gt=0, description="default (estimate_from_frames): target extent / 130")
    source_voxel_m: float | None = Field(None, gt=0, description="default (estimate_from_frames): target extent / 80")
    pairs_per_source: int = Field(6, ge=1, le=1000, description="later frames each source point is matched in")
    neighbours: int = Field(12, ge=5, le=100, description="points in each normal estimate")
    near_window: int = Field(2, ge=1, le=100, description="frames paired with each frame in the first stage")
    max_iterations: int = Field(20, ge=1, le=1000, description="Gauss-Newton steps per stage")
    tolerance: float = Field(1e-5, gt=0, description="stop when no parameter moves more than this (rad, rad/s, m)")


@dataclass(frozen=True)
class DenseFit:
    """Result of :func:`refine_dense`: canonical 9-vector, its 9x9 covariance, fit statistics.

    rms_m: RMS point-to-plane residual of the inliers; frame_rms_m: the same per frame (as
    source or target); residuals: inlier residuals used; sources: distinct source points.
    """

    x: FloatArray
    cov: FloatArray
    free: tuple[int, ...]
    rms_m: float
    frame_rms_m: FloatArray
    residuals: int
    sources: int
    iterations: int

    @property
    def spin_only(self) -> bool:
        return self.free == SPIN_ONLY_FREE


@dataclass(frozen=True)
class DensePoints:
    """Subsampled frames: target points with frame, line-time index, and a source subset.

    xyz_m: ``(n, 3)``; frame: ``(n,)``; line: ``(n,)`` index into ``tau_s`` (unique line
    offsets from ``T``); sources: indices of the source points into ``xyz_m``.
    """

    xyz_m: FloatArray
    frame: IntArray
    line: IntArray
    tau_s: FloatArray
    sources: IntArray
    n_frames: int

    def frame_sensor_tau(self) -> FloatArray:
        """Mean line offset of each frame (where its sensor origin is taken)."""
        t = self.tau_s[self.line]
        return np.asarray(np.bincount(self.frame, weights=t) / np.bincount(self.frame), dtype=float)


def subsample(
    xyz_m: FloatArray,
    tau_s: FloatArray,
    frame: IntArray,
    *,
    target_voxel_m: float,
    source_voxel_m: float,
    seed: int = 0,
) -> DensePoints:
    """One point per target voxel per frame, and one per source voxel of those (seeded choice)."""
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(xyz_m))
    keep = order[_one_per_voxel(xyz_m[order], frame[order], target_voxel_m)]
    keep.sort()
    xyz, f = xyz_m[keep], frame[keep]
    tau_u, line = np.unique(tau_s[keep], return_inverse=True)
    shuffled = rng.permutation(len(xyz))
    sources = np.sort(shuffled[_one_per_voxel(xyz[shuffled], f[shuffled], source_voxel_m)])
    return DensePoints(xyz, f.astype(np.int64), line.astype(np.int64), tau_u, sources, int(f.max()) + 1)


def _one_per_voxel(xyz: FloatArray, frame: IntArray, voxel_m: float) -> IntArray:
    """Index of the first point in each (frame, voxel) cell."""
    cell = np.floor((xyz - xyz.min(axis=0)) / voxel_m).astype(np.int64)
    dims = cell.max(axis=0) + 1
    key = ((frame.astype(np.int64) * dims[0] + cell[:, 0]) * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    return np.asarray(np.unique(key, return_index=True)[1], dtype=np.int64)


class _Mapping:
    """``R(tau)^T`` per line and its derivatives w.r.t. the free parameters (complex step)."""

    def __init__(self, x: FloatArray, tau_s: FloatArray, free: tuple[int, ...]) -> None:
        self.x = x
        self.Rt = _rotations_T(x.astype(complex)[None, :], tau_s)[0].real
        probes = np.tile(x.astype(complex), (len(free), 1))
        probes[np.arange(len(free)), list(free)] += 1j * STEP
        dRt = _rotations_T(probes, tau_s).imag / STEP  # (k, lines, 3, 3)
        self.free = free
        self.dRt = dRt
        self.center = x[6:9]

    def apply(self, xyz: FloatArray, line: IntArray) -> FloatArray:
        return np.asarray(self.center + np.einsum("nij,nj->ni", self.Rt[line], xyz - self.center))

    def rotate(self, v: FloatArray, line: IntArray) -> FloatArray:
        return np.asarray(np.einsum("nij,nj->ni", self.Rt[line], v))

    def derivative(self, xyz: FloatArray, line: IntArray) -> FloatArray:
        """``dM/dx_free`` for each point, ``(n, 3, k)``; the centre enters as ``(I - R^T)``."""
        v = xyz - self.center
        d = np.einsum("knij,nj->nik", self.dRt[:, line], v)
        Rt = self.Rt[line]
        for j, p in enumerate(self.free):
            if p >= 6:
                d[:, :, j] += np.eye(3)[p - 6] - Rt[:, :, p - 6]
        return np.asarray(d)


def _rotations_T(x: NDArray[np.complex128], tau_s: FloatArray) -> NDArray[np.complex128]:
    """``R(tau)^T = Rs^T Rp^T`` for parameter rows ``(k, 9)`` and offsets ``(m,)``: ``(k, m, 3, 3)``."""
    l_s = axis_from_angles(x[:, 0], x[:, 1])[:, None, :]
    l_p = axis_from_angles(x[:, 3], x[:, 4])[:, None, :]
    Rs = rotation_matrix(l_s, x[:, [2]] * tau_s)
    Rp = rotation_matrix(l_p, x[:, [5]] * tau_s)
    return np.asarray(np.swapaxes(Rp @ Rs, -1, -2))


@dataclass(frozen=True)
class _Surfaces:
    """The local plane at every target point, expressed at the point's own observation time
    (sensor frame) so it moves with the motion like the point: unit normal facing the sensor,
    anchor (centroid of the neighbours) and whether the neighbourhood is planar."""

    normal_obs: FloatArray
    anchor_obs: FloatArray
    planar: NDArray[np.bool_]


def _surfaces(points: DensePoints, mapping: _Mapping, neighbours: int) -> _Surfaces:
    """Local planes of every frame's mapped points (principal axes of ``neighbours`` points)."""
    mapped = mapping.apply(points.xyz_m, points.line)
    normal_ref = np.zeros_like(mapped)
    anchor_ref = mapped.copy()
    planar = np.zeros(len(mapped), bool)
    sensor_tau = points.frame_sensor_tau()
    for f in range(points.n_frames):
        idx = np.flatnonzero(points.frame == f)
        if len(idx) < neighbours:
            continue
        P = mapped[idx]
        _, nn = cKDTree(P).query(P, k=neighbours, workers=-1)
        centroid = P[nn].mean(axis=1)
        Q = P[nn] - centroid[:, None, :]
        w, V = np.linalg.eigh(np.einsum("nki,nkj->nij", Q, Q))
        n = V[:, :, 0]
        # The sensor origin of this frame, mapped to T, is on the visible side of each surface.
        sensor = _sensor_at_reference(mapping.x, float(sensor_tau[f]))
        n *= np.sign(np.einsum("ni,ni->n", sensor - P, n))[:, None]
        normal_ref[idx] = n
        anchor_ref[idx] = centroid
        planar[idx] = w[:, 0] <= MAX_CURVATURE * w.sum(axis=1)
    # Back to each point's observation time: v_obs = R(tau) v_ref (about the centre for positions).
    Rt = mapping.Rt[points.line]
    normal_obs = np.einsum("nji,nj->ni", Rt, normal_ref)
    anchor_obs = mapping.center + np.einsum("nji,nj->ni", Rt, anchor_ref - mapping.center)
    return _Surfaces(np.asarray(normal_obs), np.asarray(anchor_obs), planar)


def _sensor_at_reference(x: FloatArray, tau_s: float) -> FloatArray:
    Rt = _rotations_T(x.astype(complex)[None, :], np.array([tau_s]))[0, 0].real
    center = x[6:9]
    return np.asarray(center + Rt @ (-center))


@dataclass(frozen=True)
class _Matches:
    src: IntArray  # source point of each residual (also its cluster in the sandwich covariance)
    dst: IntArray


def _match(
    points: DensePoints,
    mapping: _Mapping,
    surf: _Surfaces,
    pair_sources: dict[tuple[int, int], IntArray],
    gate_m: float,
) -> _Matches:
    mapped = mapping.apply(points.xyz_m, points.line)
    normal_ref = mapping.rotate(surf.normal_obs, points.line)
    planar = surf.planar
    by_frame = [np.flatnonzero(points.frame == f) for f in range(points.n_frames)]
    trees: dict[int, cKDTree] = {}
    src_all, dst_all = [], []
    for (_, b), src in pair_sources.items():
        if b not in trees:
            trees[b] = cKDTree(mapped[by_frame[b]])
        dist, nn = trees[b].query(mapped[src], k=1, distance_upper_bound=gate_m, workers=-1)
        ok = np.isfinite(dist)
        dst = by_frame[b][nn[ok]]
        s = src[ok]
        ok2 = planar[dst] & planar[s] & (np.einsum("ni,ni->n", normal_ref[s], normal_ref[dst]) > MAX_NORMAL_ANGLE_COS)
        src_all.append(s[ok2])
        dst_all.append(dst[ok2])
    src_c = np.concatenate(src_all) if src_all else np.zeros(0, np.int64)
    dst_c = np.concatenate(dst_all) if dst_all else np.zeros(0, np.int64)
    return _Matches(src_c, dst_c)


def _residuals(points: DensePoints, mapping: _Mapping, surf: _Surfaces, m: _Matches) -> FloatArray:
    p = mapping.apply(points.xyz_m[m.src], points.line[m.src])
    q = mapping.apply(surf.anchor_obs[m.dst], points.line[m.dst])
    n = mapping.rotate(surf.normal_obs[m.dst], points.line[m.dst])
    return np.asarray(np.einsum("ni,ni->n", n, p - q))


def _jacobian(points: DensePoints, mapping: _Mapping, surf: _Surfaces, m: _Matches) -> FloatArray:
    dp = mapping.derivative(points.xyz_m[m.src], points.line[m.src])
    dq = mapping.derivative(surf.anchor_obs[m.dst], points.line[m.dst])
    n = mapping.rotate(surf.normal_obs[m.dst], points.line[m.dst])
    return np.asarray(np.einsum("ni,nik->nk", n, dp - dq))


def _cauchy_weights(r: FloatArray, sigma: float) -> FloatArray:
    return np.asarray(1.0 / (1.0 + (r / (CAUCHY_C * sigma)) ** 2))


def _robust_sigma(r: FloatArray) -> float:
    return float(1.4826 * np.median(np.abs(r))) if len(r) else 0.0


@dataclass
class _Problem:
    points: DensePoints
    free: tuple[int, ...]
    base: FloatArray
    config: DenseConfig
    gauge_point: FloatArray | None
    noise_floor_m: float

    def full(self, z: FloatArray) -> FloatArray:
        x = self.base.copy()
        x[list(self.free)] = z
        return x


def refine_dense(
    points: DensePoints,
    x0: FloatArray,
    *,
    spin_only: bool = False,
    config: DenseConfig | None = None,
    noise_floor_m: float = 0.01,
    seed: int = 0,
    on_iteration: Callable[[int, int], None] | None = None,
) -> DenseFit:
    """Refine ``x0`` (a 9-vector at the reference time of ``points.tau_s``); see the module docstring.

    points: subsampled frames (:func:`subsample`). spin_only: fix the precession rate at 0
    and pin the centre on the spin axis nearest the sources' centroid. noise_floor_m: the
    correspondence gate never shrinks below 5 times this (about the range noise).
    on_iteration(step, max_steps): called after each step; it may raise to stop.
    """
    cfg = config or DenseConfig()
    free = SPIN_ONLY_FREE if spin_only else ALL_FREE
    base = np.asarray(x0, dtype=float).copy()
    gauge = None
    if spin_only:
        base[3:6] = 0.0
        gauge = _Mapping(base, points.tau_s, free).apply(points.xyz_m, points.line)[points.sources].mean(axis=0)
    problem = _Problem(points, free, base, cfg, gauge, noise_floor_m)
    rng = np.random.default_rng(seed)
    z = base[list(free)]
    total = 2 * cfg.max_iterations
    step = 0
    # 1. Near frames only: right correspondences even from the initializer's rough start.
    near = _pair_sources(points, rng, window=cfg.near_window, per_source=1)
    z, _, _, step = _iterate(problem, z, near, step=step, total=total, on_iteration=on_iteration)
    # 2. Every frame with later ones: long baselines pin the rates down.
    far = _pair_sources(points, rng, window=None, per_source=cfg.pairs_per_source)
    z, matches, surf, step = _iterate(problem, z, far, step=step, total=total, on_iteration=on_iteration)
    return _finish(problem, z, matches, surf, step)


def _pair_sources(
    points: DensePoints, rng: np.random.Generator, *, window: int | None, per_source: int
) -> dict[tuple[int, int], IntArray]:
    """For each frame pair ``(a, b > a)`` within ``window``, the sources of ``a`` to match in ``b``:
    each source point goes to ``per_source`` of its frame's partners, chosen at random."""
    out: dict[tuple[int, int], list[int]] = {}
    F = points.n_frames
    for a in range(F - 1):
        partners = np.arange(a + 1, F if window is None else min(F, a + 1 + window))
        src = points.sources[points.frame[points.sources] == a]
        k = min(per_source, len(partners))
        if len(partners) == 0 or len(src) == 0:
            continue
        choice = np.argsort(rng.random((len(src), len(partners))), axis=1)[:, :k]
        for j, b in enumerate(partners):
            sel = src[(choice == j).any(axis=1)]
            if len(sel):
                out.setdefault((a, int(b)), []).extend(sel.tolist())
    return {key: np.asarray(v, dtype=np.int64) for key, v in out.items()}


def _iterate(
    problem: _Problem,
    z: FloatArray,
    pair_sources: dict[tuple[int, int], IntArray],
    *,
    step: int,
    total: int,
    on_iteration: Callable[[int, int], None] | None,
) -> tuple[FloatArray, _Matches, _Surfaces, int]:
    cfg = problem.config
    points = problem.points
    floor = 5 * problem.noise_floor_m
    gate = max(_extent(points) / 20, floor)
    mapping = _Mapping(problem.full(z), points.tau_s, problem.free)
    surf = _surfaces(points, mapping, cfg.neighbours)
    matches = _match(points, mapping, surf, pair_sources, gate)
    n_rot = sum(p < 6 for p in problem.free)
    drift = 0.0
    for _ in range(cfg.max_iterations):
        r = _residuals(points, mapping, surf, matches)
        J = _jacobian(points, mapping, surf, matches)
        sigma = max(_robust_sigma(r), problem.noise_floor_m / 10)
        w = _cauchy_weights(r, sigma)
        rows, rhs = J * np.sqrt(w)[:, None], -r * np.sqrt(w)
        rows, rhs = _with_gauge(problem, mapping, rows, rhs)
        dz = np.linalg.lstsq(rows, rhs, rcond=None)[0]
        z = z + dz
        step += 1
        if on_iteration is not None:
            on_iteration(step, total)
        moved = float(np.max(np.abs(dz)))
        drift += np.abs(dz[:n_rot]).max(initial=0.0)
        mapping = _Mapping(problem.full(z), points.tau_s, problem.free)
        # Tighten the gate as the frames come together, and refresh the normals once the rotation has moved.
        gate = max(floor, min(gate, 4 * CAUCHY_C * sigma))
        if drift > NORMAL_REFRESH_RAD:
            surf = _surfaces(points, mapping, cfg.neighbours)
            drift = 0.0
        matches = _match(points, mapping, surf, pair_sources, gate)
        if moved < cfg.tolerance:
            break
    return z, matches, surf, step


def _gauge_row(problem: _Problem, x: FloatArray) -> FloatArray | None:
    """Spin-only: ``d/dz [l_s . (O - gauge_point)]`` (the centre's slide along the spin axis), else None."""
    if problem.gauge_point is None:
        return None
    row = np.zeros(len(problem.free))
    row[list(problem.free).index(6) :] = axis_from_angles(x[0], x[1])
    return row


def _with_gauge(
    problem: _Problem, mapping: _Mapping, rows: FloatArray, rhs: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Spin-only: one heavy row pinning the centre to the axis point nearest the gauge point."""
    row = _gauge_row(problem, mapping.x)
    if row is None or problem.gauge_point is None:
        return rows, rhs
    x = mapping.x
    weight = 1e3 * max(float(np.sqrt(np.mean(rows**2))), 1.0)
    g_val = -float(row[-3:] @ (x[6:9] - problem.gauge_point)) * weight
    return np.vstack([rows, row * weight]), np.append(rhs, g_val)


def _extent(points: DensePoints) -> float:
    return float(np.linalg.norm(np.ptp(points.xyz_m, axis=0)))


def _finish(problem: _Problem, z: FloatArray, m: _Matches, surf: _Surfaces, steps: int) -> DenseFit:
    """Covariance and residual statistics at ``z`` with the last step's correspondences."""
    points = problem.points
    x = problem.full(z)
    mapping = _Mapping(x, points.tau_s, problem.free)
    r = _residuals(points, mapping, surf, m)
    J = _jacobian(points, mapping, surf, m)
    sigma = max(_robust_sigma(r), 1e-15)
    w = _cauchy_weights(r, sigma)
    cov_free = _sandwich(J, r, w, m.src, _gauge_row(problem, x))
    cov9 = np.zeros((N_PARAMS, N_PARAMS))
    idx = np.array(problem.free)
    cov9[np.ix_(idx, idx)] = cov_free
    inlier = np.abs(r) <= 3 * sigma
    frame_sq = np.zeros(points.n_frames)
    frame_n = np.zeros(points.n_frames)
    for fr in (points.frame[m.src], points.frame[m.dst]):
        np.add.at(frame_sq, fr[inlier], r[inlier] ** 2)
        np.add.at(frame_n, fr[inlier], 1)
    frame_rms = np.sqrt(frame_sq / np.maximum(frame_n, 1))
    frame_rms[frame_n == 0] = np.nan
    return DenseFit(
        x=canonical_params(x),
        cov=canonical_cov(x, cov9),
        free=problem.free,
        rms_m=float(np.sqrt(np.mean(r[inlier] ** 2))) if inlier.any() else float("nan"),
        frame_rms_m=frame_rms,
        residuals=len(r),
        sources=len(np.unique(m.src)),
        iterations=steps,
    )


def _sandwich(
    J: FloatArray, r: FloatArray, w: FloatArray, cluster: IntArray, gauge_row: FloatArray | None
) -> FloatArray:
    """``H^-1 B H^-1``: ``H = J^T W J``, ``B`` sums each source point's gradient outer product."""
    Jw = J * w[:, None]
    H = J.T @ Jw
    g = Jw * r[:, None]
    _, inv = np.unique(cluster, return_inverse=True)
    G = np.zeros((int(inv.max()) + 1 if len(inv) else 0, J.shape[1]))
    np.add.at(G, inv, g)
    B = G.T @ G
    if gauge_row is not None:
        # The gauge row fixes the centre's slide along the spin axis (see _with_gauge).
        H = H + np.outer(gauge_row, gauge_row) * 1e6 * np.trace(H)
    Hinv = np.linalg.pinv(H, rcond=1e-12)
    return np.asarray(Hinv @ B @ Hinv, dtype=float)
