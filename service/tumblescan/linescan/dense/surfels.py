"""Surfels: small planar patches of each frame, and the per-line rotations that move them.

Each frame is cut into cells of the sensor's view (direction, not 3D: a 3D voxel whose face
cuts a surface keeps the points that range noise pushed inside, and its centroid sits off the
surface). With a motion ``x``, every point ``p`` seen at ``t = T + tau`` maps to the reference
time as ``M(p, tau; x) = O_p + R(tau)^T (p - O_p)``; a surfel's points mapped so give its
centroid and normal, and the surfel is attached to the line of its mean time so that it moves
with the motion like a point.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.spatial import cKDTree

from ..._typing import FloatArray, IntArray
from ...geometry.rotations import axis_from_angles, rotation_matrix
from ..sensor import SensorNoise, azimuth_elevation
from .curvature import CURVATURE_RADIUS, foot_offset
from .faces import (
    NEIGHBOUR_OFFSETS,
    SIDE_NEIGHBOURS,
    CellPlanes,
    assign_to_faces,
    beside_face,
    clear_of_other_faces,
    clear_of_outlines,
    flat_cells,
    inside_face,
)
from .returns import range_inliers

STEP = 1e-20  # complex-step size: exact derivatives, no cancellation
# Neighbouring cells of one surface differ in range by less than this many surfel sizes.
MAX_RANGE_STEP = 4.0
# Far returns (:func:`~.returns.range_inliers`) up to this share of the points are taken for the
# minorities of cells across an occlusion (0.2 % of clean simulated frames) and kept: leaving
# those out let cells at edges pass for planar, and on the 100 m bench error/sigma rose from
# 1.04 to 1.16. More than this are spurious returns and are left out.
SPURIOUS_MIN_SHARE = 0.01
# A surfel's normal pools the planar cells of every frame within this many surfel sizes (at T)
# whose own normals agree within this angle.
SHARED_RADIUS = 1.5
# Incidence beyond this cosine counts as grazing (the along-ray noise grows as tan^2).
MIN_COS_INCIDENCE = 0.15
NOISE_COV_PASSES = 2
SHARED_MAX_ANGLE = np.radians(30.0)
# The points of the cells left out beside an outline are not handed to other cells (build_surfels).
KEEP_EDGE_POINTS_OUT = True
CURVATURE_CORRECTION = True  # anchors on the surface, not at the centroids (curvature.py)
# Points mapped to T per chunk of this many (LineMapping.apply): the gathered rotations stay in cache.
APPLY_CHUNK = 65536
# Rows per chunk of LineMapping.normal_derivative: its (rows, 9, parameters) gather stays in cache.
DERIVATIVE_CHUNK = 4096


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
    neighbours: IntArray  # (m, 8) the cells around each in its frame's view, -1 where none
    # The input's points kept (:func:`prepare` leaves spurious returns out); None: all of them.
    kept: NDArray[np.bool_] | None = None

    @cached_property
    def own_cell_lines(self) -> tuple[FloatArray, IntArray]:
        """Each cell's point count and the line nearest its points' mean time: the same for
        every surfel build (read only)."""
        return _cell_lines(self.tau_s, self.line, self.cell, len(self.cell_frame))

    @property
    def spurious(self) -> int:
        """How many of the input's points were left out as spurious returns."""
        return 0 if self.kept is None else int(np.sum(~self.kept))

    def first_frames(self, n: int) -> DenseData:
        """The same data restricted to frames ``0 .. n-1``."""
        if n >= self.n_frames:
            return self
        keep = self.frame < n
        kept_cells = self.cell_frame < n
        new_cell = np.cumsum(kept_cells) - 1
        nb = self.neighbours[kept_cells]
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
            np.where(nb >= 0, new_cell[nb], -1).astype(np.int64),
        )


def prepare(
    xyz_m: FloatArray, tau_s: FloatArray, frame: IntArray, *, surfel_m: float, range_sigma_m: float | None = None
) -> DenseData:
    """Group points into lines (distinct ``tau_s``) and surfels: per frame, cells of the
    sensor's view about ``surfel_m`` wide at the median range. Cells are cut in direction, not
    in 3D, because membership must not depend on the range noise: a voxel whose face cuts a
    surface keeps the points that noise pushed inside, and its centroid is biased off the surface.
    Given the sensor's ``range_sigma_m``, spurious returns (a range far outside the rest of its
    cell's, :func:`~.returns.range_inliers`) are left out when they are more than ``SPURIOUS_MIN_SHARE``
    of the points: a few of them make a cell fail every planarity test."""
    az, el = azimuth_elevation(xyz_m)
    range_m = np.linalg.norm(xyz_m, axis=1)
    step = surfel_m / float(np.median(range_m))
    a = np.floor((az - az.min()) / step).astype(np.int64)
    e = np.floor((el - el.min()) / step).astype(np.int64)
    f = frame.astype(np.int64)
    dims = (a.max() + 3, e.max() + 3)  # one empty cell of margin either side
    key = (f * dims[0] + a + 1) * dims[1] + e + 1
    keys, first, cell = np.unique(key, return_index=True, return_inverse=True)
    # The interior test reads every return's range, spurious or not: a cell across an
    # occlusion stays off the interior even when its far minority is left out below.
    rho = np.bincount(cell, range_m) / np.bincount(cell)
    neighbours = _view_neighbours(keys, dims[1])
    kept = None if range_sigma_m is None else range_inliers(cell, range_m, range_sigma_m, neighbours)
    if kept is not None and np.mean(~kept) <= SPURIOUS_MIN_SHARE:
        kept = None
    # Every cell keeps its median return, so the cells (and their order) stay as they are.
    sel = slice(None) if kept is None else kept
    tau_u, line = np.unique(tau_s[sel], return_inverse=True)
    xyz = np.asarray(xyz_m, dtype=float)[sel]
    return DenseData(
        xyz,
        f[sel],
        line.astype(np.int64),
        tau_u,
        cell[sel].astype(np.int64),
        f[first],
        int(f.max()) + 1,
        surfel_m,
        float(np.linalg.norm(np.ptp(xyz, axis=0))),
        _interior(neighbours, rho, max_step_m=MAX_RANGE_STEP * surfel_m),
        neighbours,
        kept,
    )


def _view_neighbours(keys: IntArray, stride: int) -> IntArray:
    """Index of the 8 cells around each cell of a frame's view, ``-1`` where none was hit;
    column ``k`` is the offset ``NEIGHBOUR_OFFSETS[k]`` in (azimuth, elevation) cells."""
    out = np.full((len(keys), 8), -1, dtype=np.int64)
    for k, (da, de) in enumerate(NEIGHBOUR_OFFSETS):
        offset = da * stride + de
        nb = keys + offset
        pos = np.clip(np.searchsorted(keys, nb), 0, len(keys) - 1)
        out[:, k] = np.where(keys[pos] == nb, pos, -1)
    return out


def _interior(neighbours: IntArray, rho_m: FloatArray, *, max_step_m: float) -> NDArray[np.bool_]:
    """Cells whose 4 neighbours in the view were hit too, at nearly the same range: not on the
    edge of the field of view, of the target's silhouette or of an occlusion, where a partner
    frame sees a different part of the scene and a match would land on the wrong surface.
    (Taking silhouette cells as well, 5-8 % more points, made the precession axis worse on the
    truss, the dish and the telescope: 0.11 -> 0.46, 0.05 -> 0.13, 0.26 -> 0.45 deg.)"""
    side = neighbours[:, list(SIDE_NEIGHBOURS)]
    near = np.abs(rho_m[np.maximum(side, 0)] - rho_m[:, None]) <= max_step_m
    return np.asarray(np.all((side >= 0) & near, axis=1))


class LineMapping:
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
        # The centre (parameters 6-8) does not enter R: its columns are zero, not probed.
        turning = [j for j, p in enumerate(self.free) if p < 6]
        probes = np.tile(self.x.astype(complex), (len(turning), 1))
        probes[np.arange(len(turning)), [self.free[j] for j in turning]] += 1j * STEP
        dRt = np.zeros((len(self.tau_s), 9, len(self.free)))
        step = _rotations_T(probes, self.tau_s).imag / STEP  # (turning, lines, 3, 3)
        dRt[:, :, turning] = step.transpose(1, 2, 3, 0).reshape(len(self.tau_s), 9, len(turning))
        return dRt

    @cached_property
    def _rows(self) -> FloatArray:
        """``R(tau)^T`` per line as 9 contiguous rows ``(9, lines)``: entry ``3a + b`` of every line."""
        return np.ascontiguousarray(self.Rt.reshape(len(self.tau_s), 9).T)

    def apply(self, xyz: FloatArray, line: IntArray) -> FloatArray:
        return self._turned(xyz, line, center=self.center, about_center=False)

    def apply_about_center(self, xyz: FloatArray, line: IntArray) -> FloatArray:
        """``apply(xyz, line) - center``, rounded as that is (the surfel build works about the centre)."""
        return self._turned(xyz, line, center=self.center, about_center=True)

    def rotate(self, v: FloatArray, line: IntArray) -> FloatArray:
        return self._turned(v, line, center=None, about_center=False)

    def _turned(self, xyz: FloatArray, line: IntArray, *, center: FloatArray | None, about_center: bool) -> FloatArray:
        """``O_p + R^T (p - O_p)`` per row (``R^T p`` without a ``center``), less ``O_p`` when
        ``about_center``. The lines' entries are gathered in chunks that stay in cache, and each
        row's products summed in the order ``b = 0, 1, 2``, as the einsum over the gathered
        ``(n, 3, 3)`` did (same rounding, half the time on the millions of points a surfel
        build maps)."""
        rows = self._rows
        out = np.empty((len(xyz), 3))
        for s in range(0, len(xyz), APPLY_CHUNK):
            v = (xyz[s : s + APPLY_CHUNK] if center is None else xyz[s : s + APPLY_CHUNK] - center).T
            ln = line[s : s + APPLY_CHUNK]
            o = out[s : s + APPLY_CHUNK]
            for a in range(3):
                o[:, a] = rows[3 * a][ln] * v[0] + rows[3 * a + 1][ln] * v[1] + rows[3 * a + 2][ln] * v[2]
            if center is not None:
                o += center
                if about_center:
                    o -= center
        return out

    def normal_derivative(self, n: FloatArray, xyz: FloatArray, line: IntArray) -> FloatArray:
        """``n . dM(xyz, line)/dx_free`` for each row, ``(rows, k)``; the centre enters as ``(I - R^T)``."""
        v = xyz - self.center
        out = np.zeros((len(xyz), len(self.free)))
        dRt = self.dRt
        # Each row's lines' derivatives gathered once per chunk that stays in cache (not once
        # per entry of R^T over every row), summed in the same order.
        for s in range(0, len(xyz), DERIVATIVE_CHUNK):
            part = dRt[line[s : s + DERIVATIVE_CHUNK]]
            o, n_s, v_s = out[s : s + DERIVATIVE_CHUNK], n[s : s + DERIVATIVE_CHUNK], v[s : s + DERIVATIVE_CHUNK]
            for a in range(3):
                for b in range(3):
                    o += (n_s[:, a] * v_s[:, b])[:, None] * part[:, 3 * a + b]
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


def normal_variance(noise: SensorNoise, xyz_obs: FloatArray, n_obs: FloatArray) -> FloatArray:
    """Variance of a measured point along the unit normal ``n_obs``: range noise along the
    line of sight ``u`` and angle noise across it, ``s_r^2 (n.u)^2 + (s_a rho)^2 (1 - (n.u)^2)``."""
    rho = np.linalg.norm(xyz_obs, axis=1)
    cos2 = (np.einsum("ni,ni->n", xyz_obs, n_obs) / np.maximum(rho, 1e-300)) ** 2
    return np.asarray(noise.range_sigma_m**2 * cos2 + (noise.angle_sigma_rad * rho) ** 2 * (1 - cos2))


def _facing_sensor(normal_obs: FloatArray, anchor_obs: FloatArray) -> FloatArray:
    """Normals flipped, where needed, to face the sensor (at the origin of its own frame)."""
    return np.asarray(normal_obs * np.where(np.einsum("ni,ni->n", normal_obs, anchor_obs) > 0, -1.0, 1.0)[:, None])


def _shared_normals(
    mean: FloatArray,
    cov: FloatArray,
    noise_cov: FloatArray,
    count: FloatArray,
    normal: FloatArray,
    use: NDArray[np.bool_],
    *,
    radius_m: float,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Normals of the cells ``use`` (at ``T``) from the pooled moments of every used cell, of
    any frame, whose centroid lies within ``radius_m`` and whose normal agrees within
    ``SHARED_MAX_ANGLE`` (which keeps the other face of an edge, or of a thin panel, out):
    ``(k, 3)`` normals, ``(k,)`` pooled count times in-plane variance and ``(k, 3)`` the pooled
    centroids (where each normal holds: on a curved surface, the pooled points' centre)."""
    idx = np.flatnonzero(use)
    tree = cKDTree(mean[idx])
    pairs = tree.query_pairs(radius_m, output_type="ndarray")
    # Each pair's agreement once for both of its directions (the same products and sums).
    used_normal = normal[idx]
    limit = np.cos(SHARED_MAX_ANGLE)
    pair_ok = np.einsum("ni,ni->n", used_normal[pairs[:, 0]], used_normal[pairs[:, 1]]) > limit
    self_ok = np.einsum("ni,ni->n", used_normal, used_normal) > limit
    a, b, own = pairs[pair_ok, 0], pairs[pair_ok, 1], np.flatnonzero(self_ok)
    i = np.concatenate([a, b, own])
    j = np.concatenate([b, a, own])
    n = count[idx]
    m = mean[idx]
    moments = np.concatenate(
        [
            n[:, None],
            n[:, None] * m,
            (n[:, None, None] * (cov[idx] + m[:, :, None] * m[:, None, :])).reshape(-1, 9),
            (n[:, None, None] * noise_cov[idx]).reshape(-1, 9),
        ],
        axis=1,
    )
    pooled = sparse.csr_matrix((np.ones(len(i)), (i, j)), shape=(len(idx), len(idx))) @ moments
    total = pooled[:, 0]
    centre = pooled[:, 1:4] / total[:, None]
    scatter = pooled[:, 4:13].reshape(-1, 3, 3) / total[:, None, None] - centre[:, :, None] * centre[:, None, :]
    w, V = np.linalg.eigh(scatter - pooled[:, 13:22].reshape(-1, 3, 3) / total[:, None, None])
    return np.asarray(V[:, :, 0]), np.asarray(total * np.maximum(w[:, 1], 0.0)), np.asarray(centre)


def _noise_cov(noise: SensorNoise, xyz_obs: FloatArray, normal_obs: FloatArray) -> FloatArray:
    """Covariance of a cell's points about the surface, ``(n, 3, 3)``, in the sensor frame.

    A cell holds the points whose *measured* direction falls in it, so angle noise does not
    spread them across the line of sight: it moves each along its measured ray, to the range
    of the surface where the true ray hit, ``rho tan(theta)`` per radian for a surface whose
    normal is ``theta`` from the line of sight ``u``. Hence all the noise lies along ``u``:
    ``(s_r^2 + (s_a rho tan theta)^2) u u^T`` (along the normal this is the same variance as
    :func:`normal_variance`)."""
    rho = np.linalg.norm(xyz_obs, axis=1)
    u = xyz_obs / np.maximum(rho, 1e-300)[:, None]
    cos2 = np.maximum(np.einsum("ni,ni->n", u, normal_obs) ** 2, MIN_COS_INCIDENCE**2)
    along = noise.range_sigma_m**2 + (noise.angle_sigma_rad * rho) ** 2 * (1 - cos2) / cos2
    return np.asarray(along[:, None, None] * u[:, :, None] * u[:, None, :])


@dataclass(frozen=True)
class Surfels:
    """Every surfel at its own line's observation time (sensor frame): anchor (a planar
    surfel's: the surface point under its centroid, :func:`curvature.foot_offset`; any other's: the
    centroid), unit normal facing the sensor, line, point count, whether it is planar, and the
    sensor variance of one of its points along the normal."""

    anchor_obs: FloatArray
    normal_obs: FloatArray
    line: IntArray
    count: FloatArray
    planar: NDArray[np.bool_]
    var_m2: FloatArray
    normal_var_rad2: FloatArray
    mapping: LineMapping  # the motion they were built with
    # Each point's surfel ``(n,)``: its cell, or the neighbour on whose face it lies when its
    # own cell straddles an edge (:func:`~.faces.assign_to_faces`).
    point_cell: IntArray


def _cell_lines(tau_s: FloatArray, point_line: IntArray, cell: IntArray, m: int) -> tuple[FloatArray, IntArray]:
    """Count ``(m,)`` of each cell's points and the line nearest their mean time ``(m,)``
    (``tau_s`` per line, ``point_line`` per point)."""
    count = np.bincount(cell, minlength=m).astype(float)
    tau_mean = np.bincount(cell, tau_s[point_line], minlength=m) / np.maximum(count, 1)
    line = np.clip(np.searchsorted(tau_s, tau_mean), 0, len(tau_s) - 1)
    lower = np.maximum(line - 1, 0)
    line = np.where(np.abs(tau_s[lower] - tau_mean) < np.abs(tau_s[line] - tau_mean), lower, line)
    return count, line


def _cell_moments(
    data: DenseData, mapped: FloatArray, cell: IntArray, m: int, *, only: NDArray[np.bool_] | None = None
) -> tuple[FloatArray, FloatArray, FloatArray, IntArray]:
    """Count ``(m,)``, centroid ``(m, 3)`` and scatter ``(m, 3, 3)`` of each cell's points
    ``mapped`` (at ``T``, less the centre), and the line nearest their mean time ``(m,)``.

    only: the cells ``(m,)`` whose moments are wanted; the rows of the others are zero. A cell's
    sums run over its points in the same order either way, so its moments are the same to the
    last bit, at the cost of its points alone."""
    point_line = data.line
    if only is not None:
        sel = np.flatnonzero(only[cell])
        cell, mapped, point_line = cell[sel], mapped[sel], point_line[sel]
    if only is None and cell is data.cell:
        count, line = data.own_cell_lines
    else:
        count, line = _cell_lines(data.tau_s, point_line, cell, m)
    safe = np.maximum(count, 1)
    mean = np.stack([np.bincount(cell, mapped[:, i], minlength=m) for i in range(3)], axis=1) / safe[:, None]
    cov = np.empty((m, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            s = np.bincount(cell, mapped[:, i] * mapped[:, j], minlength=m) / safe - mean[:, i] * mean[:, j]
            cov[:, i, j] = cov[:, j, i] = s
    return count, mean, cov, line


def _noise_free_normals(
    cov: FloatArray, Rt: FloatArray, anchor_obs: FloatArray, noise: SensorNoise
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Each cell's raw scatter eigenvalues ``(m, 3)`` ascending, its unit normal at ``T`` facing
    the sensor ``(m, 3)``, from the scatter ``cov`` less the sensor noise's, and that noise's
    covariance at ``T`` ``(m, 3, 3)``. The noise lies along the ray and depends on the normal
    (:func:`_noise_cov`): start from the raw scatter's thinnest axis and refine. ``Rt``:
    ``R(tau)^T`` of each cell's line."""
    w, V = np.linalg.eigh(cov)
    normal_ref = V[:, :, 0]
    for _ in range(NOISE_COV_PASSES):
        normal_obs = np.einsum("nji,nj->ni", Rt, normal_ref)
        noise_ref = np.einsum("nij,njk,nlk->nil", Rt, _noise_cov(noise, anchor_obs, normal_obs), Rt)
        normal_ref = np.linalg.eigh(cov - noise_ref)[1][:, :, 0]
    normal_obs = _facing_sensor(np.einsum("nji,nj->ni", Rt, normal_ref), anchor_obs)
    return w, np.asarray(np.einsum("nij,nj->ni", Rt, normal_obs)), noise_ref


def _tilt_variance(var_m2: FloatArray, spread_m2: FloatArray) -> FloatArray:
    """A plane's normal tilt from noise (rad²): the sensor's variance along the normal ``var_m2``
    over the in-plane spread of its points, ``spread_m2`` (count × the middle eigenvalue)."""
    return np.asarray(var_m2 / np.maximum(spread_m2, 1e-300))


def build_surfels(data: DenseData, mapping: LineMapping, noise: SensorNoise) -> Surfels:
    """Moments of each cell's points mapped to ``T``: centroid, and normal from the scatter less
    the sensor's; which cells are planar; then the points of the cells across edges handed to
    the planar cells of their faces (:func:`~.faces.assign_to_faces`), and the moments again."""
    m = len(data.cell_frame)
    origin = mapping.center
    mapped = mapping.apply_about_center(data.xyz_m, data.line)
    count, mean, cov, line = _cell_moments(data, mapped, data.cell, m)
    # Back to the observation time: v_obs = R(tau) v_ref (about the centre for positions).
    Rt = mapping.Rt[line]
    anchor_obs = origin + np.einsum("nji,nj->ni", Rt, mean)
    # Range noise stretches every surfel along the line of sight, which tilts the thinnest
    # axis of its scatter towards it (by degrees, and differently in every frame as the target
    # turns): the normal is taken from the scatter less the noise's covariance.
    w, normal_ref, noise_ref = _noise_free_normals(cov, Rt, anchor_obs, noise)
    normal_obs = np.einsum("nji,nj->ni", Rt, normal_ref)
    var = normal_variance(noise, anchor_obs, normal_obs)
    flat = flat_cells(w, var, count)
    spread = count * np.maximum(w[:, 1], 0.0)
    tilt_var = _tilt_variance(var, spread)
    planar = flat & data.interior & inside_face(data.neighbours, normal_obs, count, flat, tilt_var, data.interior)
    planes = CellPlanes(data.neighbours, data.cell, mapped, mean, normal_ref, var, tilt_var, count)
    planar |= beside_face(planes, flat & data.interior & ~planar, planar)
    # The cells that may hold a few points of another face, within the noise of their plane.
    planar = clear_of_other_faces(planes, planar, planar)
    outline = planar & ~clear_of_outlines(data.neighbours, count, data.interior, planar)
    planar &= ~outline
    # Nor are the points of the cells beside an outline handed over (unless KEEP_EDGE_POINTS_OUT
    # is off): the other face's among them lie on this face's plane too, and no neighbour's plane
    # tells them apart, so they joined the neighbours' surfels instead. The band along an edge
    # between two faces' planes is assign_to_faces' own to keep out.
    givers = data.interior & ~planar & ~(outline & KEEP_EDGE_POINTS_OUT)
    # One cell's normal is tilted by degrees of noise, and an eigenvector's error has a bias of
    # the order of its variance: take it from every frame's planar cells nearby instead (with
    # the cells across edges left out above, these all lie on one face). These are the planes
    # the points of the other cells are tested against, and they are pooled again when cells
    # gain points.
    pooled_ref = normal_ref.copy()
    pooled_spread = spread.copy()
    pooled_ref[planar], pooled_spread[planar], _ = _shared_normals(
        mean, cov, noise_ref, count, normal_ref, planar, radius_m=SHARED_RADIUS * data.surfel_m
    )
    pooled = replace(planes, normal_ref=pooled_ref, tilt_var_rad2=_tilt_variance(var, pooled_spread))
    point_cell = assign_to_faces(pooled, givers, planar)
    moved = point_cell != data.cell
    if np.any(moved):
        # The cells that gained or lost points: their moments, line and normal again.
        changed = np.zeros(m, dtype=bool)
        changed[point_cell[moved]] = changed[data.cell[moved]] = True
        new_count, new_mean, new_cov, new_line = _cell_moments(data, mapped, point_cell, m, only=changed)
        count = np.where(changed, new_count, count)
        mean = np.where(changed[:, None], new_mean, mean)
        cov = np.where(changed[:, None, None], new_cov, cov)
        line = np.where(changed, new_line, line)
        Rt = mapping.Rt[line]
        anchor_obs = origin + np.einsum("nji,nj->ni", Rt, mean)
        w[changed], normal_ref[changed], noise_ref[changed] = _noise_free_normals(
            cov[changed], Rt[changed], anchor_obs[changed], noise
        )
        normal_obs = np.einsum("nji,nj->ni", Rt, normal_ref)
        spread = count * np.maximum(w[:, 1], 0.0)
        pooled_ref[planar], spread[planar], pooled_centre = _shared_normals(
            mean, cov, noise_ref, count, normal_ref, planar, radius_m=SHARED_RADIUS * data.surfel_m
        )
    else:
        spread[planar] = pooled_spread[planar]
        pooled_centre = _shared_normals(
            mean, cov, noise_ref, count, normal_ref, planar, radius_m=SHARED_RADIUS * data.surfel_m
        )[2]
    shared = pooled_ref[planar]
    normal_obs[planar] = _facing_sensor(np.einsum("nji,nj->ni", Rt[planar], shared), anchor_obs[planar])
    if CURVATURE_CORRECTION and np.any(planar):
        # The centroid of a cell on a curved surface lies off it, by half the curvature times
        # the points' in-plane spread; move it onto the surface (see curvature.foot_offset).
        normal_t = np.einsum("nij,nj->ni", Rt[planar], normal_obs[planar])  # at T, facing the sensor
        shift = foot_offset(
            pooled_centre,
            normal_t,
            cov[planar] - noise_ref[planar],
            radius_m=CURVATURE_RADIUS * data.surfel_m,
            max_angle_rad=SHARED_MAX_ANGLE,
        )
        anchor_obs[planar] += shift[:, None] * normal_obs[planar]
    var = normal_variance(noise, anchor_obs, normal_obs)
    normal_var = _tilt_variance(var, spread)
    return Surfels(anchor_obs, normal_obs, line.astype(np.int64), count, planar, var, normal_var, mapping, point_cell)
