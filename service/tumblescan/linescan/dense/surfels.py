"""Surfels: small planar patches of each frame, one per cell of the sensor's view (:mod:`.data`).

A cell's points, mapped to the reference time with the motion (:mod:`.mapping`), give its
centroid and normal; the surfel is attached to the line of its mean time so that it moves with
the motion like a point. Only cells that are flat, interior and inside a face (:mod:`.faces`)
take part in the fit.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.spatial import cKDTree

from ..._typing import FloatArray, IntArray
from ..sensor import SensorNoise
from .curvature import CURVATURE_RADIUS, foot_offset
from .data import DenseData, cell_lines
from .faces import (
    CellPlanes,
    beside_face,
    clear_of_other_faces,
    clear_of_outlines,
    flat_cells,
    inside_face,
)
from .handover import assign_to_faces
from .mapping import LineMapping

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
    # own cell straddles an edge (:func:`~.handover.assign_to_faces`).
    point_cell: IntArray


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
        count, line = cell_lines(data.tau_s, point_line, cell, m)
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
    the planar cells of their faces (:func:`~.handover.assign_to_faces`), and the moments again."""
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
    planes = CellPlanes(
        data.neighbours,
        data.cell,
        mapped,
        mean,
        normal_ref,
        var,
        tilt_var,
        count,
        data.xyz_m,
        data.line,
        mapping,
        noise.angle_sigma_rad**2,
    )
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
