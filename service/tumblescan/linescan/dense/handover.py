"""The hand-over: the points of cells that are not on one face (across an edge, beside a boom, on
the silhouette) go to the neighbouring surfel of the face they lie on.

Which face a point near an edge lies on is read off where its line of sight meets the two faces'
planes, which the point's own noise does not move (:func:`_seen_planes`); deciding by the point's
offsets from the planes sorted the points by the sign of their noise and biased the surfels that
took them in.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from ..._typing import FloatArray, IntArray
from .faces import BESIDE_MAX_SIGMAS, CellPlanes, normal_tolerance

# The pairs of a cell's 8 neighbours, and each pair's first and second neighbour as index arrays.
NEIGHBOUR_PAIRS = tuple((a, b) for a in range(8) for b in range(a + 1, 8))
PAIR_A, PAIR_B = (np.array(side) for side in zip(*NEIGHBOUR_PAIRS, strict=True))


def assign_to_faces(planes: CellPlanes, candidate: NDArray[np.bool_], face: NDArray[np.bool_]) -> IntArray:
    """Each point's cell ``(n,)``, with the points of the ``candidate`` cells (not on one face:
    across an edge, beside a boom, on the silhouette) handed to the neighbouring ``face`` cell
    on whose plane they lie.

    A point ``p`` (``mapped_m`` at ``T``) of a candidate cell lies on the plane of a
    neighbour ``k`` inside a face when
    ``z^2 = (n_k . (p - c_k))^2 / (v_k (1 + 1 / N_k) + t_k |p - c_k|_perp^2) <= BESIDE_MAX_SIGMAS^2``
    (the point's noise along ``n_k``, the plane's offset and its tilt ``t_k`` over the in-plane
    offset: ``var_m2``, ``count``, ``tilt_var_rad2`` of ``k``). Of the neighbours whose planes
    its line of sight may meet on their face (:func:`_seen_planes`: across an edge, the one the
    line sees, decided by where it meets each plane, not by the point's noise), it goes to the one
    nearest along its plane, when it lies on that plane, unless a point on no neighbour's plane
    (another surface, whose own cells are not planar: a face seen edge-on, a boom) lies within
    ``BESIDE_MAX_SIGMAS`` sigmas ``sqrt(v_k)`` of it: that surface's points near the edge lie
    within the sigmas of the plane as well.

    Deciding the face by the point's own offsets (none when it lay within the sigmas of another
    face's plane too) kept the points whose noise put them off that plane: beside a ridge they
    lay 0.21 range sigmas nearer the sensor on average, beside a valley as far beyond
    (tests/linescan/dense/test_surfels.py), and the surfels that took them in were biased the
    same way in every frame (docs/linescan-rounds.md, twelfth round).

    So the points of either face of a cell that straddles an edge join their face's surfel,
    the band along the edge where the faces cannot be told apart stays out, and points on no
    plane stay in their cell, which is not planar.
    """
    neighbours, cell, mapped_m, mean_m = planes.neighbours, planes.cell, planes.mapped_m, planes.mean_m
    normal_ref, var_m2, tilt_var_rad2, count = planes.normal_ref, planes.var_m2, planes.tilt_var_rad2, planes.count
    point_cell = cell.copy()
    # The candidate cells with a neighbour inside a face, and each such neighbour's plane.
    nb_all = np.where(neighbours >= 0, neighbours, 0)
    valid_all = (neighbours >= 0) & face[nb_all]
    cells = np.flatnonzero(candidate & np.any(valid_all, axis=1))
    if len(cells) == 0:
        return point_cell
    nb, valid = nb_all[cells], valid_all[cells]
    n_k, c_k = normal_ref[nb], mean_m[nb]  # (c, 8, 3)
    v_k = var_m2[nb] * (1 + 1 / np.maximum(count[nb], 1))
    t_k = tilt_var_rad2[nb]
    # Which neighbours lie on different faces, (c, 8, 8).
    cos = np.abs(np.einsum("cai,cbi->cab", n_k, n_k))
    apart = cos <= np.cos(normal_tolerance(t_k[:, :, None], t_k[:, None, :]))
    compact = np.full(len(candidate), -1)
    compact[cells] = np.arange(len(cells))
    pts = np.flatnonzero(compact[cell] >= 0)
    ci = compact[cell[pts]]
    # z^2 and the squared in-plane offset of every point from the plane of each valid
    # neighbour: (point, neighbour) flattened, the neighbours' planes as one table of c * 8 rows.
    z2_flat = np.full(len(pts) * 8, np.inf)
    in_plane2_flat = np.full(len(pts) * 8, np.inf)
    pair = np.flatnonzero(valid[ci].reshape(-1))
    p = pair // 8
    q = ci[p] * 8 + pair % 8
    offset = mapped_m[pts[p]] - c_k.reshape(-1, 3)[q]
    n_q = n_k.reshape(-1, 3)[q]
    d = np.einsum("ni,ni->n", offset, n_q)
    in_plane2_flat[pair] = np.einsum("ni,ni->n", offset, offset) - d**2
    z2_flat[pair] = d**2 / (v_k.reshape(-1)[q] + t_k.reshape(-1)[q] * in_plane2_flat[pair])
    z2, in_plane2 = z2_flat.reshape(-1, 8), in_plane2_flat.reshape(-1, 8)
    gate = BESIDE_MAX_SIGMAS**2
    on_plane = np.min(z2, axis=1) <= gate
    # The receiver is the nearest along its plane of the surfels the line of sight may meet, not
    # the best-fitting: that would sort the points by the sign of their noise (the surfels' planes
    # differ by their own noise): on the folded wall the centroids of the surfels that took points
    # in were 4 standard errors off their face (rms), against 1.0 elsewhere. (Only a point on some
    # plane can lie on the receiver's, so only those are weighed.)
    fit = np.flatnonzero(on_plane)
    cf, zf = ci[fit], z2[fit]
    rows = np.arange(len(fit))
    seen = valid[cf]
    # Where two of a cell's neighbours lie on different faces, its points' lines of sight decide
    # which they may lie on (a tenth to a half of the candidate cells' points).
    across = apart[:, PAIR_A, PAIR_B] & valid[:, PAIR_A] & valid[:, PAIR_B]  # (c, 28)
    e = np.flatnonzero(np.any(across, axis=1)[cf])
    if len(e):
        ce = cf[e]
        u, rho2 = sight_lines(planes, pts[fit[e]])
        # The offsets of these few points again, rather than every pair's scattered into a table.
        offset_e = mapped_m[pts[fit[e]]][:, None, :] - c_k[ce]
        nu = np.einsum("eki,ei->ek", n_k[ce], u)
        sight = SightLines(
            np.einsum("eki,eki->ek", offset_e, n_k[ce]),
            np.where(np.abs(nu) < 1e-6, -1e-6, nu),
            planes.angle_var_rad2 * rho2,
        )
        kinds = _edge_kinds(n_k, c_k, across, u, ce)
        plane_var = var_m2[nb] / np.maximum(count[nb], 1)
        seen[e] = _seen_planes(sight, in_plane2[fit[e]], zf[e], seen[e], ce, kinds, plane_var, t_k)
    recv = np.argmin(np.where(seen, in_plane2[fit], np.inf), axis=1)
    take = np.zeros(len(pts), dtype=bool)
    take[fit] = seen[rows, recv] & (zf[rows, recv] <= gate)
    k = np.zeros(len(pts), dtype=np.int64)
    k[fit] = nb[cf, recv]
    if not np.any(take):
        return point_cell
    # Points on no neighbour's plane, of every frame: another frame cuts the edge elsewhere, or
    # sees the other surface where this one does not (with this frame's only, 2.2 times the
    # points of another face were handed over on the box at 100 m).
    off = candidate[cell]
    off[pts[on_plane]] = False
    if np.any(off):
        reach = BESIDE_MAX_SIGMAS * np.sqrt(var_m2[k[take]])
        tree = cKDTree(mapped_m[off], balanced_tree=False, compact_nodes=False)
        dist, _ = tree.query(mapped_m[pts[take]], distance_upper_bound=float(reach.max()), workers=-1)
        take[take] = dist > reach
    point_cell[pts[take]] = k[take]
    return point_cell


def sight_lines(planes: CellPlanes, pts: IntArray) -> tuple[FloatArray, FloatArray]:
    """The unit line of sight of each point ``pts`` at ``T`` ``(p, 3)`` (the sensor at the
    origin of its own frame; :meth:`~.mapping.LineMapping.rotate` turns its measured direction),
    and its squared range ``(p,)``."""
    xyz = planes.xyz_obs[pts]
    u = planes.mapping.rotate(xyz, planes.line[pts])
    rho2 = np.einsum("ni,ni->n", xyz, xyz)
    return u / np.sqrt(rho2)[:, None], rho2


def edge_kind(
    n_a: FloatArray, n_b: FloatArray, gap: FloatArray, u: FloatArray
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Whether two planes (unit normals ``n_a``, ``n_b``, either sign; ``gap`` from ``a``'s
    centroid to ``b``'s) meet at a convex edge, each centroid behind the other's plane as seen
    along ``u``, or a concave one, each in front."""
    facing_a = n_a * -np.sign(np.einsum("...i,...i->...", n_a, u))[..., None]
    facing_b = n_b * -np.sign(np.einsum("...i,...i->...", n_b, u))[..., None]
    behind_a = np.einsum("...i,...i->...", facing_a, gap) < 0  # b's centroid behind a's plane
    behind_b = np.einsum("...i,...i->...", facing_b, gap) > 0
    return np.asarray(behind_a & behind_b), np.asarray(~behind_a & ~behind_b)


def line_sees(
    diff: FloatArray, var: FloatArray, convex: NDArray[np.bool_], concave: NDArray[np.bool_]
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Which of two planes a line of sight sees, ``(sees_a, sees_b)``, from how much farther along
    it plane ``a`` lies than ``b`` (``diff = delta_a - delta_b``) and that difference's variance
    ``var``: across a convex edge the farther plane, across a concave one the nearer, and neither
    when ``diff`` is within ``BESIDE_MAX_SIGMAS`` of its sigmas."""
    clear = diff**2 > BESIDE_MAX_SIGMAS**2 * var
    sees_a = clear & ((convex & (diff > 0)) | (concave & (diff < 0)))
    sees_b = clear & ((convex & (diff < 0)) | (concave & (diff > 0)))
    return np.asarray(sees_a), np.asarray(sees_b)


@dataclass(frozen=True)
class SightLines:
    """Per point and neighbour ``(p, 8)``: the plane's offset ``d`` from the point along its
    normal and the normal's cosine ``nu`` with the line of sight; per point ``(p,)``, the line's
    angle noise across it at the point's range, ``lateral_var`` (``(s_a rho)^2``, m²)."""

    d: FloatArray
    nu: FloatArray
    lateral_var: FloatArray


@dataclass(frozen=True)
class EdgeKinds:
    """Per candidate cell and pair of its neighbours (``NEIGHBOUR_PAIRS``), ``(c, 28)``: whether
    both are inside a face and their planes lie on different faces (``across``), whether each
    one's centroid lies behind the other's plane (``convex``) or both in front (``concave``), and
    their normals' dot product."""

    across: NDArray[np.bool_]
    convex: NDArray[np.bool_]
    concave: NDArray[np.bool_]
    dot: FloatArray


def _edge_kinds(n_k: FloatArray, c_k: FloatArray, across: NDArray[np.bool_], u: FloatArray, ce: IntArray) -> EdgeKinds:
    """:class:`EdgeKinds` of the candidate cells' neighbours' planes (normals ``n_k`` and
    centroids ``c_k``, ``(c, 8, 3)``; ``across``, ``(c, 28)``, the pairs on different faces), the
    normals turned to face the sensor along the line of sight ``u`` of one of the cell's points
    (``ce``: each line's cell)."""
    one = np.zeros(len(n_k), dtype=np.int64)
    one[ce] = np.arange(len(ce))
    a, b = PAIR_A, PAIR_B
    convex, concave = edge_kind(n_k[:, a], n_k[:, b], c_k[:, b] - c_k[:, a], u[one][:, None, :])
    dot = np.einsum("cji,cji->cj", n_k[:, a], n_k[:, b])
    return EdgeKinds(across, convex, concave, dot)


def _seen_planes(
    sight: SightLines,
    in_plane2: FloatArray,
    z2: FloatArray,
    valid: NDArray[np.bool_],
    cell: IntArray,
    kinds: EdgeKinds,
    plane_var: FloatArray,
    tilt_var: FloatArray,
) -> NDArray[np.bool_]:
    """Which of their neighbours' planes ``(p, 8)`` points may lie on, decided by where each
    point's line of sight meets them, which its range noise does not move.

    A point ``p`` lies on its line of sight ``u`` (at ``T``); plane ``k`` meets that line
    ``delta_k = -n_k . (p - c_k) / (n_k . u)`` beyond it. Noise moves ``p`` along ``u`` (range,
    and angle noise at the surface's range, :func:`~.surfels._noise_cov`), which moves every
    ``delta_k`` alike: ``delta_a - delta_b`` is the same for every draw of it. Across a convex
    edge (each plane's centroid behind the other's plane, normals facing the sensor) the line
    sees the farther of the two planes, across a concave one the nearer: a plane the line does
    not see, by more than ``BESIDE_MAX_SIGMAS`` sigmas, is not the point's. The sigma is the
    planes' own noise along the line (``plane_var`` of their offset and ``tilt_var`` times
    ``in_plane2``, over ``(n_k . u)^2``) and the line's angle noise across them
    (``lateral_var |n_a / (n_a . u) - n_b / (n_b . u)|^2``). A pair of planes that is neither
    (one in front of the other) keeps the test on the point: it lies on neither plane when it
    lies within the sigmas of both (``z2``).

    in_plane2, z2, valid (the neighbours inside a face): ``(p, 8)``; cell: ``(p,)`` each point's
    row of ``kinds``, ``plane_var`` and ``tilt_var`` ``(c, 8)``.
    """
    lost = ~valid
    gate = BESIDE_MAX_SIGMAS**2
    for j, (a, b) in enumerate(NEIGHBOUR_PAIRS):
        idx = np.flatnonzero(kinds.across[cell, j])
        if len(idx) == 0:
            continue
        c = cell[idx]
        ia, ib = 1 / sight.nu[idx, a], 1 / sight.nu[idx, b]
        diff = sight.d[idx, b] * ib - sight.d[idx, a] * ia  # delta_a - delta_b
        var = (plane_var[c, a] + tilt_var[c, a] * in_plane2[idx, a]) * ia**2
        var += (plane_var[c, b] + tilt_var[c, b] * in_plane2[idx, b]) * ib**2
        var += sight.lateral_var[idx] * (ia**2 + ib**2 - 2 * kinds.dot[c, j] * ia * ib)
        sees_a, sees_b = line_sees(diff, var, kinds.convex[c, j], kinds.concave[c, j])
        mixed = ~(kinds.convex[c, j] | kinds.concave[c, j])
        lost[idx, a] |= ~(sees_a | (mixed & (z2[idx, b] > gate)))
        lost[idx, b] |= ~(sees_b | (mixed & (z2[idx, a] > gate)))
    return np.asarray(~lost)
