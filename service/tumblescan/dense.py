"""Dense continuous-time refinement of the motion from line-scan frames (beyond the paper).

Every point ``p`` seen at ``t = T + tau`` maps to the reference time as

    M(p, tau; x) = O_p + R(tau)^T (p - O_p)

and with the right motion the mapped frames coincide. Each frame is cut into surfels, cells
of the sensor's view about ``surfel_m`` wide (cut in direction, so that range noise cannot
move a point from one cell to another). A surfel's points, mapped to ``T`` with the current
motion, give its centroid ``a`` and normal ``n`` (principal axes); the surfel is attached to
the line of its mean time, so it moves with the motion like a point. For a source surfel
``a_s`` of one frame and the nearest planar surfel ``(a_t, n_t)`` of another, the residual is
the centroid-to-plane distance

    r = n_t(x) . (a_s(x) - a_t(x)),
    var r = s^2 (v_s / N_s + v_t / N_t + d^2 v_n)

with ``v`` the sensor's variance along ``n_t`` (range noise along the line of sight, angle
noise across it, ``SensorNoise``), ``N`` the surfels' point counts, ``d`` the in-plane offset
between the centroids, ``v_n`` the variance of the target normal's tilt, and ``s`` a common
scale estimated from the residuals. A centroid carries what its points say along the normal,
so every point of a planar surfel enters the fit at the cost of one residual per partner.
The fit minimizes the Cauchy loss of ``r / sqrt(var r)`` over the 9 motion parameters by
Levenberg-Marquardt steps, with correspondences re-found once points have moved and the
surfels rebuilt after large steps.

Three stages: every surfel matched in the next frames only (right correspondences even from
the initializer's rough start), then in random frames (the long time baselines fix the
rates), then in more random frames from the converged start (each brings its own noise).

Covariance: the sandwich ``H^-1 (sum_c g_c g_c^T) H^-1`` with ``H = J^T W J`` and ``g_c`` the
gradient of all residuals of source surfel ``c`` (one surfel enters several pairs, so its
noise is counted once).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field
from scipy.spatial import cKDTree

from .motion import N_PARAMS, axis_from_angles, canonical_params, rotation_matrix
from .sensor import SensorNoise, azimuth_elevation
from .uncertainty import canonical_cov

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

ALL_FREE = tuple(range(N_PARAMS))
SPIN_ONLY_FREE = (0, 1, 2, 6, 7, 8)
STEP = 1e-20  # complex-step size: exact derivatives, no cancellation
CAUCHY_C = 2.385  # Cauchy constant for 95 % efficiency under Gaussian noise
MAX_NORMAL_ANGLE_COS = np.cos(np.radians(45.0))
# A surfel is planar when its thinnest axis is this much thinner than the next one and no
# thicker than a few sensor sigmas (an edge or a corner is thick for its size).
MAX_FLATNESS = 0.3
MAX_THICKNESS_SIGMAS = 2.5
MIN_SURFEL_POINTS = 6
# Neighbouring cells of one surface differ in range by less than this many surfel sizes.
MAX_RANGE_STEP = 4.0
# Rebuild the surfels, and re-find correspondences, once points have moved this share of a surfel.
SURFEL_REFRESH = 0.25
REMATCH = 0.05
PROBE_POINTS = 2000
# Levenberg-Marquardt damping: start undamped, tighten on a rise of the cost, relax on success.
LM_START = 0.0
LM_FIRST_TIGHT = 1e-4
LM_TIGHTEN = 10.0
LM_RELAX = 3.0
LM_TRIES = 10
# Spin-only covariance: the centre's unobservable slide along the spin axis is removed by a
# penalty this stiff (x trace H) before inverting.
GAUGE_STIFFNESS = 1e6


class DenseConfig(BaseModel):
    """Sampling and iteration settings of the dense refinement (lengths in metres)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    surfel_m: float | None = Field(None, gt=0, description="surfel size; default (estimate_from_frames): extent / 100")
    partners: int = Field(2, ge=1, le=100, description="other frames each surfel is matched in (second stage)")
    fine_partners: int = Field(
        14, ge=1, le=100, description="other frames each surfel is matched in (last stage; all of them if fewer)"
    )
    near_window: int = Field(2, ge=1, le=100, description="frames either side matched in the first stage")
    max_iterations: int = Field(15, ge=1, le=1000, description="Gauss-Newton steps in each of the first two stages")
    fine_iterations: int = Field(6, ge=1, le=1000, description="Gauss-Newton steps in the last stage")
    tolerance: float = Field(
        0.1, gt=0, le=1, description="stop a stage when no parameter moves more than this many standard deviations"
    )


@dataclass(frozen=True)
class DenseFit:
    """Result of :func:`refine_dense`: canonical 9-vector, its 9x9 covariance, fit statistics.

    rms_m: RMS centroid-to-plane residual of the inliers; frame_rms_m: the same per frame (as
    source or target); residuals: residuals used; surfels: distinct source surfels; points:
    the points in them.
    """

    x: FloatArray
    cov: FloatArray
    free: tuple[int, ...]
    rms_m: float
    frame_rms_m: FloatArray
    residuals: int
    surfels: int
    points: int
    iterations: int

    @property
    def spin_only(self) -> bool:
        return self.free == SPIN_ONLY_FREE


@dataclass(frozen=True)
class DenseData:
    """Every point of the frames with its line time and surfel.

    xyz_m: ``(n, 3)`` sensor frame at observation; frame: ``(n,)``; line: ``(n,)`` index into
    ``tau_s`` (distinct offsets from ``T``, s); cell: ``(n,)`` surfel index; cell_frame:
    ``(m,)`` frame of each surfel.
    """

    xyz_m: FloatArray
    frame: IntArray
    line: IntArray
    tau_s: FloatArray
    cell: IntArray
    cell_frame: IntArray
    n_frames: int
    surfel_m: float
    extent_m: float
    interior: NDArray[np.bool_]

    def first_frames(self, n: int) -> DenseData:
        """The same data restricted to frames ``0 .. n-1``."""
        if n >= self.n_frames:
            return self
        keep = self.frame < n
        kept_cells = self.cell_frame < n
        new_cell = np.cumsum(kept_cells) - 1
        return DenseData(
            self.xyz_m[keep],
            self.frame[keep],
            self.line[keep],
            self.tau_s,
            new_cell[self.cell[keep]].astype(np.int64),
            self.cell_frame[kept_cells],
            n,
            self.surfel_m,
            self.extent_m,
            self.interior[kept_cells],
        )


def prepare(xyz_m: FloatArray, tau_s: FloatArray, frame: IntArray, *, surfel_m: float) -> DenseData:
    """Group points into lines (distinct ``tau_s``) and surfels: per frame, cells of the
    sensor's view about ``surfel_m`` wide at the median range. Cells are cut in direction, not
    in 3D, because membership must not depend on the range noise: a voxel whose face cuts a
    surface keeps the points that noise pushed inside, and its centroid is biased off the surface."""
    tau_u, line = np.unique(tau_s, return_inverse=True)
    az, el = azimuth_elevation(xyz_m)
    step = surfel_m / float(np.median(np.linalg.norm(xyz_m, axis=1)))
    a = np.floor((az - az.min()) / step).astype(np.int64)
    e = np.floor((el - el.min()) / step).astype(np.int64)
    f = frame.astype(np.int64)
    dims = (a.max() + 3, e.max() + 3)  # one empty cell of margin either side
    key = (f * dims[0] + a + 1) * dims[1] + e + 1
    keys, first, cell = np.unique(key, return_index=True, return_inverse=True)
    rho = np.bincount(cell, np.linalg.norm(xyz_m, axis=1)) / np.bincount(cell)
    return DenseData(
        np.asarray(xyz_m, dtype=float),
        f,
        line.astype(np.int64),
        tau_u,
        cell.astype(np.int64),
        f[first],
        int(f.max()) + 1,
        surfel_m,
        float(np.linalg.norm(np.ptp(xyz_m, axis=0))),
        _interior(keys, rho, dims[1], max_step_m=MAX_RANGE_STEP * surfel_m),
    )


def _interior(keys: IntArray, rho_m: FloatArray, stride: int, *, max_step_m: float) -> NDArray[np.bool_]:
    """Cells whose 4 neighbours in the view were hit too, at nearly the same range: not on the
    edge of the field of view, of the target's silhouette or of an occlusion, where a partner
    frame sees a different part of the scene and a match would land on the wrong surface."""
    ok = np.ones(len(keys), bool)
    for offset in (-stride, stride, -1, 1):
        nb = keys + offset
        pos = np.clip(np.searchsorted(keys, nb), 0, len(keys) - 1)
        ok &= (keys[pos] == nb) & (np.abs(rho_m[pos] - rho_m) <= max_step_m)
    return ok


class _Mapping:
    """``R(tau)^T`` per line and its derivatives w.r.t. the free parameters (complex step)."""

    def __init__(self, x: FloatArray, tau_s: FloatArray, free: tuple[int, ...]) -> None:
        self.x = x
        self.tau_s = tau_s
        self.Rt = _rotations_T(x.astype(complex)[None, :], tau_s)[0].real
        self.free = free
        self.center = x[6:9]

    @cached_property
    def dRt(self) -> FloatArray:
        """``(lines, 9, k)``: row ``3a + b`` holds ``d(R^T)[a, b]`` for each free parameter."""
        probes = np.tile(self.x.astype(complex), (len(self.free), 1))
        probes[np.arange(len(self.free)), list(self.free)] += 1j * STEP
        dRt = _rotations_T(probes, self.tau_s).imag / STEP  # (k, lines, 3, 3)
        return np.ascontiguousarray(dRt.transpose(1, 2, 3, 0).reshape(len(self.tau_s), 9, len(self.free)))

    def apply(self, xyz: FloatArray, line: IntArray) -> FloatArray:
        return np.asarray(self.center + np.einsum("nij,nj->ni", self.Rt[line], xyz - self.center))

    def rotate(self, v: FloatArray, line: IntArray) -> FloatArray:
        return np.asarray(np.einsum("nij,nj->ni", self.Rt[line], v))

    def normal_derivative(self, n: FloatArray, xyz: FloatArray, line: IntArray) -> FloatArray:
        """``n . dM(xyz, line)/dx_free`` for each row, ``(rows, k)``; the centre enters as ``(I - R^T)``."""
        v = xyz - self.center
        out = np.zeros((len(xyz), len(self.free)))
        for a in range(3):
            for b in range(3):
                out += (n[:, a] * v[:, b])[:, None] * self.dRt[line, 3 * a + b]
        Rtn = np.einsum("nab,na->nb", self.Rt[line], n)
        for j, p in enumerate(self.free):
            if p >= 6:
                out[:, j] += n[:, p - 6] - Rtn[:, p - 6]
        return out


def _rotations_T(x: NDArray[np.complex128], tau_s: FloatArray) -> NDArray[np.complex128]:
    """``R(tau)^T = Rs^T Rp^T`` for parameter rows ``(k, 9)`` and offsets ``(m,)``: ``(k, m, 3, 3)``."""
    l_s = axis_from_angles(x[:, 0], x[:, 1])[:, None, :]
    l_p = axis_from_angles(x[:, 3], x[:, 4])[:, None, :]
    Rs = rotation_matrix(l_s, x[:, [2]] * tau_s)
    Rp = rotation_matrix(l_p, x[:, [5]] * tau_s)
    return np.asarray(np.swapaxes(Rp @ Rs, -1, -2))


def _normal_variance(noise: SensorNoise, xyz_obs: FloatArray, n_obs: FloatArray) -> FloatArray:
    """Variance of a measured point along the unit normal ``n_obs``: range noise along the
    line of sight ``u`` and angle noise across it, ``s_r^2 (n.u)^2 + (s_a rho)^2 (1 - (n.u)^2)``."""
    rho = np.linalg.norm(xyz_obs, axis=1)
    cos2 = (np.einsum("ni,ni->n", xyz_obs, n_obs) / np.maximum(rho, 1e-300)) ** 2
    return np.asarray(noise.range_sigma_m**2 * cos2 + (noise.angle_sigma_rad * rho) ** 2 * (1 - cos2))


def _planar(w: FloatArray, var: FloatArray, count: FloatArray) -> NDArray[np.bool_]:
    """Surfels flat for their size and no thicker than a few sensor sigmas (eigenvalues ``w``
    ascending; an edge or a corner is thick)."""
    thin = w[:, 0]
    return np.asarray(
        (count >= MIN_SURFEL_POINTS) & (thin <= MAX_FLATNESS * w[:, 1]) & (thin <= MAX_THICKNESS_SIGMAS**2 * var)
    )


def _noise_cov(noise: SensorNoise, xyz_obs: FloatArray) -> FloatArray:
    """Sensor covariance of a point at ``xyz_obs`` (its own frame), ``(n, 3, 3)``: range noise
    along the line of sight, angle noise across it."""
    rho = np.linalg.norm(xyz_obs, axis=1)
    u = xyz_obs / np.maximum(rho, 1e-300)[:, None]
    uu = u[:, :, None] * u[:, None, :]
    across = (noise.angle_sigma_rad * rho) ** 2
    return np.asarray(noise.range_sigma_m**2 * uu + across[:, None, None] * (np.eye(3) - uu))


@dataclass(frozen=True)
class _Surfels:
    """Every surfel at its own line's observation time (sensor frame): centroid, unit normal
    facing the sensor, line, point count, whether it is planar, and the sensor variance of one
    of its points along the normal."""

    anchor_obs: FloatArray
    normal_obs: FloatArray
    line: IntArray
    count: FloatArray
    planar: NDArray[np.bool_]
    var_m2: FloatArray
    normal_var_rad2: FloatArray
    mapping: _Mapping  # the motion they were built with


def _surfels(data: DenseData, mapping: _Mapping, noise: SensorNoise) -> _Surfels:
    """Voxel moments of the points mapped to ``T``; normals are the thinnest principal axes."""
    m = len(data.cell_frame)
    origin = mapping.center
    mapped = mapping.apply(data.xyz_m, data.line) - origin
    count = np.bincount(data.cell, minlength=m).astype(float)
    safe = np.maximum(count, 1)
    mean = np.stack([np.bincount(data.cell, mapped[:, i], minlength=m) for i in range(3)], axis=1) / safe[:, None]
    cov = np.empty((m, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            s = np.bincount(data.cell, mapped[:, i] * mapped[:, j], minlength=m) / safe - mean[:, i] * mean[:, j]
            cov[:, i, j] = cov[:, j, i] = s
    # Each surfel takes the line nearest its points' mean time.
    tau_mean = np.bincount(data.cell, data.tau_s[data.line], minlength=m) / safe
    line = np.clip(np.searchsorted(data.tau_s, tau_mean), 0, len(data.tau_s) - 1)
    lower = np.maximum(line - 1, 0)
    line = np.where(np.abs(data.tau_s[lower] - tau_mean) < np.abs(data.tau_s[line] - tau_mean), lower, line)
    # Back to the observation time: v_obs = R(tau) v_ref (about the centre for positions).
    Rt = mapping.Rt[line]
    anchor_obs = origin + np.einsum("nji,nj->ni", Rt, mean)
    # Range noise stretches every surfel along the line of sight, which tilts the thinnest
    # axis of its scatter towards it (by degrees, and differently in every frame as the target
    # turns): the normal is taken from the scatter less the sensor's own covariance.
    w, _ = np.linalg.eigh(cov)
    _, V = np.linalg.eigh(cov - np.einsum("nij,njk,nlk->nil", Rt, _noise_cov(noise, anchor_obs), Rt))
    normal_obs = np.einsum("nji,nj->ni", Rt, V[:, :, 0])
    # The sensor is at the origin of its own frame: normals face it.
    normal_obs *= np.where(np.einsum("ni,ni->n", normal_obs, anchor_obs) > 0, -1.0, 1.0)[:, None]
    var = _normal_variance(noise, anchor_obs, normal_obs)
    planar = _planar(w, var, count)
    planar &= data.interior
    # The normal's tilt from noise: the sensor's variance along it over the in-plane spread.
    normal_var = var / (np.maximum(count, 1) * np.maximum(w[:, 1], 1e-300))
    return _Surfels(anchor_obs, normal_obs, line.astype(np.int64), count, planar, var, normal_var, mapping)


@dataclass(frozen=True)
class _Matches:
    src: IntArray  # source surfel of each residual (also its cluster in the sandwich covariance)
    dst: IntArray  # target surfel


def _match(
    data: DenseData,
    mapping: _Mapping,
    surf: _Surfels,
    src: IntArray,
    partner: IntArray,
    gate_m: float,
) -> _Matches:
    """Nearest planar surfel of the partner frame for each (source, partner) pair, if it lies
    within ``gate_m`` and faces the same way as the source's own surfel."""
    anchor_ref = mapping.apply(surf.anchor_obs, surf.line)
    normal_ref = mapping.rotate(surf.normal_obs, surf.line)
    usable = surf.planar[src]
    src, partner = src[usable], partner[usable]
    mapped = anchor_ref[src]
    src_all, dst_all = [], []
    for b in range(data.n_frames):
        sel = np.flatnonzero(partner == b)
        targets = np.flatnonzero((data.cell_frame == b) & surf.planar)
        if len(sel) == 0 or len(targets) == 0:
            continue
        dist, nn = cKDTree(anchor_ref[targets]).query(mapped[sel], k=1, distance_upper_bound=gate_m, workers=-1)
        ok = np.isfinite(dist)
        dst = targets[nn[ok]]
        s = sel[ok]
        facing = np.einsum("ni,ni->n", normal_ref[src[s]], normal_ref[dst]) > MAX_NORMAL_ANGLE_COS
        src_all.append(src[s[facing]])
        dst_all.append(dst[facing])
    src_c = np.concatenate(src_all) if src_all else np.zeros(0, np.int64)
    dst_c = np.concatenate(dst_all) if dst_all else np.zeros(0, np.int64)
    return _Matches(src_c, dst_c)


@dataclass(frozen=True)
class _Linearized:
    r: FloatArray  # centroid-to-plane residuals (m)
    J: FloatArray  # their derivatives w.r.t. the free parameters
    var: FloatArray  # model variance of each residual (m^2), before the common scale


def _residuals(
    data: DenseData, mapping: _Mapping, surf: _Surfels, m: _Matches
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Centroid-to-plane residuals, the plane normals at ``T`` and the squared in-plane offsets.

    The plane's normal is the mean of both surfels' (a symmetric objective): the normal's
    noise times the in-plane offset between the centroids is the largest term of a residual's
    variance, and the mean halves it."""
    p = mapping.apply(surf.anchor_obs[m.src], surf.line[m.src])
    q = mapping.apply(surf.anchor_obs[m.dst], surf.line[m.dst])
    n = mapping.rotate(surf.normal_obs[m.dst], surf.line[m.dst]) + mapping.rotate(
        surf.normal_obs[m.src], surf.line[m.src]
    )
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    d = p - q
    r = np.einsum("ni,ni->n", n, d)
    return np.asarray(r), n, np.asarray(np.einsum("ni,ni->n", d, d) - r**2)


def _linearize(data: DenseData, mapping: _Mapping, surf: _Surfels, m: _Matches, noise: SensorNoise) -> _Linearized:
    xyz, line = surf.anchor_obs[m.src], surf.line[m.src]
    r, n, offset2 = _residuals(data, mapping, surf, m)
    J = mapping.normal_derivative(n, xyz, line) - mapping.normal_derivative(n, surf.anchor_obs[m.dst], surf.line[m.dst])
    # The source centroid's noise along the normal, seen from the source's own sensor; the
    # target centroid's; and the normal's tilt over the offset between the two.
    n_src_obs = np.einsum("nji,nj->ni", mapping.Rt[line], n)
    var = (
        _normal_variance(noise, xyz, n_src_obs) / surf.count[m.src]
        + surf.var_m2[m.dst] / surf.count[m.dst]
        + offset2 * (surf.normal_var_rad2[m.src] + surf.normal_var_rad2[m.dst]) / 4
    )
    return _Linearized(np.asarray(r), J, np.asarray(var))


def _cauchy_weights(e: FloatArray, scale: float) -> FloatArray:
    return np.asarray(1.0 / (1.0 + (e / (CAUCHY_C * scale)) ** 2))


def _robust_sigma(r: FloatArray) -> float:
    return float(1.4826 * np.median(np.abs(r))) if len(r) else 0.0


def _cauchy_cost(e: FloatArray, scale: float) -> float:
    c2 = (CAUCHY_C * scale) ** 2
    return float(0.5 * c2 * np.sum(np.log1p(e**2 / c2)))


def _weights(lin: _Linearized) -> tuple[FloatArray, float]:
    """Weights ``cauchy(e / s) / var`` of the normalized residuals ``e = r / sqrt(var)``, and ``s``."""
    e = lin.r / np.sqrt(lin.var)
    scale = max(_robust_sigma(e), 1e-12)
    return _cauchy_weights(e, scale) / lin.var, scale


@dataclass
class _Problem:
    data: DenseData
    free: tuple[int, ...]
    base: FloatArray
    config: DenseConfig
    noise: SensorNoise
    gauge_point: FloatArray | None

    def full(self, z: FloatArray) -> FloatArray:
        x = self.base.copy()
        x[list(self.free)] = z
        return x


def refine_dense(
    data: DenseData,
    x0: FloatArray,
    *,
    spin_only: bool = False,
    config: DenseConfig | None = None,
    noise: SensorNoise | None = None,
    seed: int = 0,
    converged: bool = False,
    gauge_point: FloatArray | None = None,
    on_iteration: Callable[[int, int], None] | None = None,
) -> DenseFit:
    """Refine ``x0`` (a 9-vector at the reference time of ``data.tau_s``); see the module docstring.

    data: the frames (:func:`prepare`). spin_only: fix the precession rate at 0 and keep the
    centre on the spin axis, at the point nearest the points' centroid. noise: the sensor's noise model
    (weights, planarity test, correspondence gate). converged: ``x0`` is already a solution
    (of a superset of these frames, say): run the last stage only, from the tightest gate.
    gauge_point: spin-only, the point whose nearest axis point is reported as the centre
    (default: the points' centroid at ``T``); give the same one to compare two fits.
    on_iteration(step, max_steps): called after each step; it may raise to stop.
    """
    cfg = config or DenseConfig()
    sensor = noise or SensorNoise()
    free = SPIN_ONLY_FREE if spin_only else ALL_FREE
    base = np.asarray(x0, dtype=float).copy()
    rng = np.random.default_rng(seed)
    gauge = None
    if spin_only:
        base[3:6] = 0.0
        every = data.xyz_m[:: max(1, len(data.xyz_m) // PROBE_POINTS)]
        every_line = data.line[:: max(1, len(data.xyz_m) // PROBE_POINTS)]
        gauge = (
            np.asarray(gauge_point, dtype=float)
            if gauge_point is not None
            else _Mapping(base, data.tau_s, free).apply(every, every_line).mean(axis=0)
        )
    problem = _Problem(data, free, base, cfg, sensor, gauge)
    base[:] = _on_gauge(problem, base)
    z = base[list(free)]
    step = 0
    cells = np.arange(len(data.cell_frame), dtype=np.int64)
    stages = [
        # 1. Neighbouring frames only: right correspondences even from a rough start.
        (_partners(data, cells, rng, window=cfg.near_window, k=1), cfg.max_iterations),
        # 2. Any frame: long baselines pin the rates down.
        (_partners(data, cells, rng, window=None, k=cfg.partners), cfg.max_iterations),
        # 3. More partners from the converged start: each brings its own target noise.
        (_partners(data, cells, rng, window=None, k=cfg.fine_partners), cfg.fine_iterations),
    ]
    surf: _Surfels | None = None
    gate = max(data.extent_m / 20, 5 * sensor.range_sigma_m, 1.5 * data.surfel_m)
    if converged:
        stages, gate = stages[2:], max(5 * sensor.range_sigma_m, 1.5 * data.surfel_m)
    total = sum(iterations for _, iterations in stages)
    for (src, partner), iterations in stages:
        z, matches, surf, gate, step = _iterate(
            problem, z, src, partner, surf, gate, iterations, step=step, total=total, on_iteration=on_iteration
        )
    assert surf is not None
    return _finish(problem, z, matches, surf, step)


def _partners(
    data: DenseData, src: IntArray, rng: np.random.Generator, *, window: int | None, k: int
) -> tuple[IntArray, IntArray]:
    """``k`` random other frames for each source surfel (within ``window`` frames of its own, if
    given): the pairs as parallel arrays ``(source, partner frame)``."""
    F = data.n_frames
    reach = F - 1 if window is None else min(window, F - 1)
    own = data.cell_frame[src]
    if window is None and k >= F - 1:
        # Every other frame, in order: nothing left to chance.
        b = (own[:, None] + np.arange(1, F)[None, :]) % F
        return np.repeat(src, F - 1), b.ravel()
    offsets = np.concatenate([-np.arange(reach, 0, -1), np.arange(1, reach + 1)])
    out_src, out_partner = [], []
    for _ in range(min(k, 2 * reach)):
        b = own + offsets[rng.integers(0, len(offsets), len(src))]
        # Offsets past either end fold back inside (a frame never pairs with itself).
        b = np.where(b < 0, -b, b)
        b = np.where(b >= F, 2 * (F - 1) - b, b)
        ok = (b != own) & (b >= 0) & (b < F)
        out_src.append(src[ok])
        out_partner.append(b[ok])
    return np.concatenate(out_src), np.concatenate(out_partner)


def _iterate(
    problem: _Problem,
    z: FloatArray,
    src: IntArray,
    partner: IntArray,
    surf: _Surfels | None,
    gate: float,
    iterations: int,
    *,
    step: int,
    total: int,
    on_iteration: Callable[[int, int], None] | None,
) -> tuple[FloatArray, _Matches, _Surfels, float, int]:
    """Gauss-Newton steps on one set of (source, partner) pairs; ``gate`` is the largest
    distance to a matched surfel's centroid, tightened as the frames come together."""
    cfg, data, noise = problem.config, problem.data, problem.noise
    floor = max(5 * noise.range_sigma_m, 1.5 * data.surfel_m)
    probe = np.arange(0, len(data.xyz_m), max(1, len(data.xyz_m) // PROBE_POINTS))
    mapping = _Mapping(problem.full(z), data.tau_s, problem.free)
    if surf is None or _shift(data, probe, surf.mapping, mapping) > SURFEL_REFRESH * data.surfel_m:
        surf = _surfels(data, mapping, noise)
    matches, matched_at, matched_gate = _match(data, mapping, surf, src, partner, gate), mapping, gate
    lam = LM_START
    for _ in range(iterations):
        lin = _linearize(data, mapping, surf, matches, noise)
        w, scale = _weights(lin)
        sw = np.sqrt(w)
        rows = lin.J * sw[:, None]
        H, g = rows.T @ rows, -rows.T @ (lin.r * sw)
        taken = _damped_step(problem, z, H, g, lam, lin, scale, matches, surf)
        if taken is None:
            break
        dz, lam, mapping = taken
        # A step far below the parameters' own uncertainty changes nothing that matters.
        sd = scale * np.sqrt(np.diag(np.linalg.pinv(H, rcond=1e-12)))
        moved = float(np.max(np.abs(dz) / np.maximum(sd, 1e-300)))
        z = z + dz
        step += 1
        if on_iteration is not None:
            on_iteration(step, total)
        if moved < cfg.tolerance:
            break
        # Tighten the gate as the frames come together. Surfels move rigidly with their lines,
        # so they are rebuilt only after large steps; correspondences once points have moved.
        gate = max(floor, min(gate, 4 * CAUCHY_C * _robust_sigma(lin.r)))
        if _shift(data, probe, surf.mapping, mapping) > SURFEL_REFRESH * data.surfel_m:
            surf = _surfels(data, mapping, noise)
        if (
            surf.mapping is mapping
            or gate < 0.9 * matched_gate
            or _shift(data, probe, matched_at, mapping) > REMATCH * data.surfel_m
        ):
            matches, matched_at, matched_gate = _match(data, mapping, surf, src, partner, gate), mapping, gate

    return z, matches, surf, gate, step


def _damped_step(
    problem: _Problem,
    z: FloatArray,
    H: FloatArray,
    g: FloatArray,
    lam: float,
    lin: _Linearized,
    scale: float,
    matches: _Matches,
    surf: _Surfels,
) -> tuple[FloatArray, float, _Mapping] | None:
    """Levenberg-Marquardt: the step ``(H + lam diag H)^-1 g`` with the smallest ``lam`` (from the
    last one) that lowers the Cauchy cost on these correspondences; None when none does."""
    data = problem.data
    before = _cauchy_cost(lin.r / np.sqrt(lin.var), scale)
    D = np.diag(np.diag(H))
    for _ in range(LM_TRIES):
        step = np.linalg.lstsq(H + lam * D, g, rcond=None)[0]
        x = _on_gauge(problem, problem.full(z + step))
        dz = x[list(problem.free)] - z
        mapping = _Mapping(x, data.tau_s, problem.free)
        r = _residuals(data, mapping, surf, matches)[0]
        after = _cauchy_cost(r / np.sqrt(lin.var), scale)
        if after <= before:
            return np.asarray(dz, dtype=float), max(lam / LM_RELAX, LM_START), mapping
        lam = max(lam * LM_TIGHTEN, LM_FIRST_TIGHT)
    return None


def _shift(data: DenseData, probe: IntArray, before: _Mapping, after: _Mapping) -> float:
    """Largest displacement of the probe points at ``T`` between two motions (m)."""
    xyz, line = data.xyz_m[probe], data.line[probe]
    return float(np.max(np.linalg.norm(after.apply(xyz, line) - before.apply(xyz, line), axis=1), initial=0.0))


def _gauge_row(problem: _Problem, x: FloatArray) -> FloatArray | None:
    """Spin-only: ``d/dz [l_s . (O - gauge_point)]`` (the centre's slide along the spin axis), else None."""
    if problem.gauge_point is None:
        return None
    row = np.zeros(len(problem.free))
    row[list(problem.free).index(6) :] = axis_from_angles(x[0], x[1])
    return row


def _on_gauge(problem: _Problem, x: FloatArray) -> FloatArray:
    """Spin-only: the centre slid along the spin axis to the point nearest the gauge point.
    Any point of the axis gives the same motion, so the cost does not change."""
    if problem.gauge_point is None:
        return x
    l_s = axis_from_angles(x[0], x[1])
    out = x.copy()
    out[6:9] -= l_s * float(l_s @ (x[6:9] - problem.gauge_point))
    return out


def _finish(problem: _Problem, z: FloatArray, m: _Matches, surf: _Surfels, steps: int) -> DenseFit:
    """Covariance and residual statistics at ``z`` with the last step's correspondences."""
    data = problem.data
    x = problem.full(z)
    mapping = _Mapping(x, data.tau_s, problem.free)
    lin = _linearize(data, mapping, surf, m, problem.noise)
    w, scale = _weights(lin)
    cov_free = _sandwich(lin.J, lin.r, w, m, _gauge_row(problem, x))
    cov9 = np.zeros((N_PARAMS, N_PARAMS))
    idx = np.array(problem.free)
    cov9[np.ix_(idx, idx)] = cov_free
    inlier = np.abs(lin.r) <= 3 * scale * np.sqrt(lin.var)
    r_in = lin.r[inlier]
    frame_sq = np.zeros(data.n_frames)
    frame_n = np.zeros(data.n_frames)
    for fr in (data.frame[m.src], data.cell_frame[m.dst]):
        np.add.at(frame_sq, fr[inlier], r_in**2)
        np.add.at(frame_n, fr[inlier], 1)
    frame_rms = np.sqrt(frame_sq / np.maximum(frame_n, 1))
    frame_rms[frame_n == 0] = np.nan
    return DenseFit(
        x=canonical_params(x),
        cov=canonical_cov(x, cov9),
        free=problem.free,
        rms_m=float(np.sqrt(np.mean(r_in**2))) if len(r_in) else float("nan"),
        frame_rms_m=frame_rms,
        residuals=len(lin.r),
        surfels=len(np.unique(m.src)),
        points=int(surf.count[np.unique(m.src)].sum()),
        iterations=steps,
    )


def _sandwich(J: FloatArray, r: FloatArray, w: FloatArray, m: _Matches, gauge_row: FloatArray | None) -> FloatArray:
    """``H^-1 B H^-1`` with ``H = J^T W J`` and ``B`` the dyadic-cluster sum: a residual carries the
    noise of two surfels (source and target), so the gradients ``g_i`` of residuals sharing a
    surfel in either role are correlated. ``B = sum_c G_c G_c^T - sum_i g_i g_i^T`` with ``G_c``
    the sum over residuals touching surfel ``c`` (each residual touches two)."""
    Jw = J * w[:, None]
    H = J.T @ Jw
    g = Jw * r[:, None]
    size = int(max(m.src.max(initial=-1), m.dst.max(initial=-1))) + 1
    G = np.zeros((size, J.shape[1]))
    np.add.at(G, m.src, g)
    np.add.at(G, m.dst, g)
    B = G.T @ G - g.T @ g
    if gauge_row is not None:
        # The centre's slide along the spin axis is fixed (see _on_gauge): no variance there.
        H = H + np.outer(gauge_row, gauge_row) * GAUGE_STIFFNESS * np.trace(H)
    Hinv = np.linalg.pinv(H, rcond=1e-12)
    return np.asarray(Hinv @ B @ Hinv, dtype=float)
