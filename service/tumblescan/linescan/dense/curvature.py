"""Where a planar surfel's anchor belongs on a curved surface: the surface point under its
centroid. A cell's centroid lies inside a convex surface (outside a concave one) by half the
curvature times its points' in-plane spread, a depth that grows with the cell's footprint and
so with the incidence: left as is, it is a bias common to a patch (issue 20's telescope).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..._typing import FloatArray
from ..sensor import perpendiculars

# A planar surfel's anchor is the surface point under its centroid, not the centroid (which
# lies inside a convex surface, outside a concave one): the curvature is fitted to the pooled
# normals of the CURVATURE_NEIGHBOURS nearest surfels, of every frame, within this many surfel
# sizes (see foot_offset).
CURVATURE_RADIUS = 2.5
CURVATURE_NEIGHBOURS = 32
# Fewer neighbours than this, or their centres spread less than this share as far across
# their narrowest direction as along their widest (a row of cells), leave the curvature at zero.
CURVATURE_MIN_NEIGHBOURS = 6
CURVATURE_MIN_SPREAD = 0.2


def foot_offset(
    centre: FloatArray, normal: FloatArray, spread: FloatArray, *, radius_m: float, max_angle_rad: float
) -> FloatArray:
    """How far along its normal each cell's centroid lies from the surface point under it,
    ``(k,)``: ``tr(K S) / 2``, with ``K`` the surface's curvature (shape operator, from the
    pooled normals: ``n_j - n_i = K (c_j - c_i)`` over the ``CURVATURE_NEIGHBOURS`` cells ``j``
    nearest ``i`` within ``radius_m`` whose normals agree within ``max_angle_rad``, least
    squares in ``i``'s tangent plane) and ``S`` the cell's in-plane scatter less the sensor noise's
    (``spread``, at ``T``).

    On a surface ``h = -p^T K p / 2`` below its tangent plane at the foot (normals facing the
    sensor, so a convex one has ``K > 0``) the points' mean height is ``-tr(K S) / 2``: the
    centroid of a convex cell lies inside by that much. Two cells' centroids then differ by
    that depth, which grows as ``1 / cos^2`` of the incidence (the cell's footprint across the
    curve): on the telescope's tube at 50 m, a cell seen at grazing incidence matched to one
    seen head-on left residuals of -3 mm (the centroid's own noise 1.2 mm) at the true motion,
    always of that sign: a bias common to a patch, which the patch-clustered covariance counts
    (reported sigmas 9-17 times the bound). The foot is where the plane of the two normals'
    mean (the residual's plane) passes through exactly for any quadric surface."""
    k = len(centre)
    nearest = min(CURVATURE_NEIGHBOURS + 1, k)
    dist, nb = cKDTree(centre).query(centre, k=nearest, distance_upper_bound=radius_m, workers=-1)
    i = np.repeat(np.arange(k), nearest).reshape(k, nearest)
    found = np.isfinite(np.asarray(dist).reshape(k, nearest)) & (i != np.asarray(nb).reshape(k, nearest))
    i, j = i[found], np.asarray(nb).reshape(k, nearest)[found]
    agree = np.einsum("ni,ni->n", normal[i], normal[j]) > np.cos(max_angle_rad)
    i, j = i[agree], j[agree]
    e1, e2 = perpendiculars(normal)  # (k, 3) each
    dp = centre[j] - centre[i]
    dn = normal[j] - normal[i]
    e1_i, e2_i = e1[i], e2[i]
    p1, p2 = np.einsum("ni,ni->n", dp, e1_i), np.einsum("ni,ni->n", dp, e2_i)
    n1, n2 = np.einsum("ni,ni->n", dn, e1_i), np.einsum("ni,ni->n", dn, e2_i)
    # Rows (p1, p2, 0) -> n1 and (0, p1, p2) -> n2 for K = [[k11, k12], [k12, k22]]: the
    # normal equations' sums per cell, each the bincount of its products (the zero entries of
    # the rows add nothing; the sums of p1 p1, p1 p2 and p2 p2 serve both rows and the spread).
    q11, q12, q22 = (np.bincount(i, u * v, minlength=k) for u, v in ((p1, p1), (p1, p2), (p2, p2)))
    M = np.zeros((k, 3, 3))
    M[:, 0, 0] = q11
    M[:, 0, 1] = M[:, 1, 0] = q12
    M[:, 1, 1] = q22 + q11  # row one's p2 p2, then row two's p1 p1
    M[:, 1, 2] = M[:, 2, 1] = q12
    M[:, 2, 2] = q22
    b = np.zeros((k, 3))
    b[:, 0] = np.bincount(i, p1 * n1, minlength=k)
    b[:, 1] = np.bincount(i, p2 * n1, minlength=k) + np.bincount(i, p1 * n2, minlength=k)
    b[:, 2] = np.bincount(i, p2 * n2, minlength=k)
    # In-plane spread of the neighbours' centres: too thin (a row of cells) leaves K unknown.
    S_pp = np.zeros((k, 2, 2))
    S_pp[:, 0, 0] = q11
    S_pp[:, 0, 1] = S_pp[:, 1, 0] = q12
    S_pp[:, 1, 1] = q22
    n_nb = np.bincount(i, minlength=k)
    spread_w = np.linalg.eigvalsh(S_pp)
    ok = (n_nb >= CURVATURE_MIN_NEIGHBOURS) & (spread_w[:, 0] >= CURVATURE_MIN_SPREAD**2 * spread_w[:, 1])
    kvec = np.zeros((k, 3))
    if np.any(ok):
        kvec[ok] = np.linalg.solve(M[ok], b[ok][:, :, None])[:, :, 0]
    s11 = np.einsum("ni,nij,nj->n", e1, spread, e1)
    s12 = np.einsum("ni,nij,nj->n", e1, spread, e2)
    s22 = np.einsum("ni,nij,nj->n", e2, spread, e2)
    return np.asarray(0.5 * (kvec[:, 0] * s11 + 2 * kvec[:, 1] * s12 + kvec[:, 2] * s22))
