"""Which cells of a frame's view make surfels: flat, and on one face of the target.

A cell across an edge passes for flat when few of its points lie on the other face, yet its
normal and centroid lean towards that face, always the same way in every frame, and bias the
fit. The tests here keep such cells out while taking in the cells beside edges, on curved
surfaces and beside thin structures, whose points lie on one face.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..._typing import FloatArray, IntArray
from .mapping import LineMapping

# A surfel is planar when its thinnest axis is this much thinner than the next one and no
# thicker than a few sensor sigmas (an edge or a corner is thick for its size).
MAX_FLATNESS = 0.3
MAX_THICKNESS_SIGMAS = 2.5
MIN_SURFEL_POINTS = 6
# The 8 cells around a cell, (azimuth, elevation) steps; the 4 that share a side with it.
NEIGHBOUR_OFFSETS = tuple((da, de) for da in (-1, 0, 1) for de in (-1, 0, 1) if da or de)
SIDE_NEIGHBOURS = tuple(k for k, (da, de) in enumerate(NEIGHBOUR_OFFSETS) if da == 0 or de == 0)
# A cell is inside a face when its 8 neighbours' normals agree with its own within this.
FACE_MAX_ANGLE = np.radians(20.0)
# A cell on a curved surface (a tube, a dish) is inside a face too when its normal field is
# smooth: every neighbour within CURVED_MAX_ANGLE, and its own normal within CURVED_MAX_KINK of
# the mean of each pair of opposite neighbours' (a curvature bends both sides alike; an edge
# bends one side only, which puts the mean half the edge's angle off).
CURVED_MAX_ANGLE = np.radians(45.0)
CURVED_MAX_KINK = np.radians(8.0)
OPPOSITE_PAIRS = tuple(
    (k, NEIGHBOUR_OFFSETS.index((-da, -de))) for k, (da, de) in enumerate(NEIGHBOUR_OFFSETS) if (da, de) > (0, 0)
)
# Two cells' normals disagree beyond FACE_MAX_ANGLE or this many sigmas of their own noise
# (a cell of 16 points at 100 m is tilted by about 7 deg), up to CURVED_MAX_ANGLE.
FACE_NOISE_SIGMAS = 3.0
# A cell beside a face (see beside_face) lies on the plane of at least this many of its
# neighbours inside the face, and each of its points within this many sigmas of it.
BESIDE_MIN_NEIGHBOURS = 2
BESIDE_MAX_SIGMAS = 3.0
# A cell beside the outline is left out when the outline's cell holds less than this share of
# its points (see clear_of_outlines).
OUTLINE_MIN_SHARE = 0.25


def flat_cells(w: FloatArray, var: FloatArray, count: FloatArray) -> NDArray[np.bool_]:
    """Surfels flat for their size and no thicker than a few sensor sigmas (eigenvalues ``w``
    ascending; an edge or a corner is thick)."""
    thin = w[:, 0]
    return np.asarray(
        (count >= MIN_SURFEL_POINTS) & (thin <= MAX_FLATNESS * w[:, 1]) & (thin <= MAX_THICKNESS_SIGMAS**2 * var)
    )


def normal_tolerance(tilt_var_rad2: FloatArray, other: FloatArray) -> FloatArray:
    """The angle two cells' normals may differ by on one face: ``FACE_MAX_ANGLE``, or
    ``FACE_NOISE_SIGMAS`` of both normals' noise, at most ``CURVED_MAX_ANGLE``."""
    return np.asarray(np.clip(FACE_NOISE_SIGMAS * np.sqrt(tilt_var_rad2 + other), FACE_MAX_ANGLE, CURVED_MAX_ANGLE))


def inside_face(
    neighbours: IntArray,
    normal_obs: FloatArray,
    count: FloatArray,
    flat: NDArray[np.bool_],
    tilt_var_rad2: FloatArray,
    interior: NDArray[np.bool_],
) -> NDArray[np.bool_]:
    """Cells whose 8 neighbours in the view were hit and face the same way (within
    :func:`normal_tolerance` of both normals' noise ``tilt_var_rad2``), or bend smoothly with them (a
    curved surface: see ``CURVED_MAX_KINK``). A cell across an edge passes for flat when few of
    its points lie on the other face, yet its normal and centroid lean towards that face, always
    the same way: one of its neighbours lies on that face, and the opposite one does not.

    A neighbour that is not ``flat`` itself (a cell across an edge thick with both faces' points,
    a corner, a thin boom) neither vouches nor objects: its normal says nothing about a face, and
    letting it object left out every cell beside an edge on both of its sides, three cells per edge
    where one straddles it (at the true motion at 100 m: 48 -> 55 % of the points on the truss,
    46 -> 52 % on Hubble, 46 -> 56 % on the dish-boom). The other face's flat cells, beyond,
    still object to a cell that straddles the edge: on the box, the accepted cells holding any
    point of another face went from 0.13 to 0.25 % of them (0.02 % of their points). Nor does a
    neighbour that is not ``interior``: a cell on the silhouette holds a strip of points whose
    normal is tilted by noise about the strip, and it vetoed the band of cells inside every
    panel's outline (Hubble at 50 m: 59 -> 62 % of the points at the true motion).

    Also tried, and left out: a neighbour across an edge not objecting when every point of the
    cell keeps clear of its plane (by 2 noise sigmas and 6 deg of tilt over a cell). It took
    4-5 % more points on the real shapes, helped the truss and harmed the dish and the
    telescope, and on the 128-pixel box test it moved the spin rate by 4 sigmas: a one-sided
    bias, as with the other ways of taking cells near edges in (docs/linescan-rounds.md)."""
    nb = neighbours
    safe = np.where(nb >= 0, nb, 0)
    cos = np.einsum("ni,nki->nk", normal_obs, normal_obs[safe])
    # A neighbour with too few points for a normal of its own, not flat, or not interior (a part
    # of a cell on the silhouette, whose normal is noisy), neither vouches nor objects.
    silent = (count[safe] < MIN_SURFEL_POINTS) | ~flat[safe] | ~interior[safe]
    tolerance = normal_tolerance(tilt_var_rad2[:, None], tilt_var_rad2[safe])
    same_face = np.all((np.abs(cos) > np.cos(tolerance)) | silent, axis=1)
    # Normals of one frame face the sensor, so they share a sign; the mean of opposite
    # neighbours' normals lies along the cell's own on a smoothly curved surface.
    smooth = np.all((cos > np.cos(CURVED_MAX_ANGLE)) | silent, axis=1)
    for a, b in OPPOSITE_PAIRS:
        mean = normal_obs[safe[:, a]] + normal_obs[safe[:, b]]
        mean /= np.maximum(np.linalg.norm(mean, axis=1, keepdims=True), 1e-300)
        kink_ok = np.einsum("ni,ni->n", normal_obs, mean) > np.cos(CURVED_MAX_KINK)
        smooth &= kink_ok | silent[:, a] | silent[:, b]
    # A cell across an edge, half on either face, has its own normal halfway between its
    # neighbours' and passes for a curve; its neighbours beside the edge do not (the mean of
    # theirs is off by a quarter of the edge's angle). On a curved surface they do.
    hit = np.all(nb >= 0, axis=1)
    one_face = hit & (same_face | smooth)
    smooth &= np.all(one_face[safe] | silent, axis=1)
    return np.asarray(hit & (same_face | smooth))


@dataclass(frozen=True)
class CellPlanes:
    """The cells' planes at ``T`` and the points in them, for :func:`beside_face` and
    :func:`.handover.assign_to_faces`: ``neighbours`` (m, 8) cell indices (-1: none), ``cell`` (n,) each
    point's cell, ``mapped_m`` (n, 3) the points at ``T``, ``mean_m`` (m, 3) centroids,
    ``normal_ref`` (m, 3) unit normals at ``T``, ``var_m2`` (m,) a point's noise variance along
    the normal, ``tilt_var_rad2`` (m,) the normal's tilt variance, ``count`` (m,) points."""

    neighbours: IntArray
    cell: IntArray
    mapped_m: FloatArray
    mean_m: FloatArray
    normal_ref: FloatArray
    var_m2: FloatArray
    tilt_var_rad2: FloatArray
    count: FloatArray
    # Each point's line of sight at ``T`` comes from its measured position ``xyz_obs`` (n, 3),
    # its ``line`` (n,) and the ``mapping`` the planes were built with.
    xyz_obs: FloatArray
    line: IntArray
    mapping: LineMapping
    angle_var_rad2: float


def beside_face(planes: CellPlanes, candidate: NDArray[np.bool_], face: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """The ``candidate`` cells (flat and interior, yet not :func:`inside_face`) that lie on the
    plane of a neighbour inside a face: their normal agrees with at least
    ``BESIDE_MIN_NEIGHBOURS`` such neighbours', and every one of their points (``mapped_m`` at
    ``T``, in ``cell``) lies within ``BESIDE_MAX_SIGMAS`` of the plane of the best agreeing one,
    its sigma the point's noise along the normal (``var_m2`` of the cell) plus the plane's own:
    its centroid's and its normal's tilt over the in-plane offset.

    Beside an edge, the inside-face test leaves out the cell that straddles it and, since that
    one objects to them, the cells either side, whose points lie on one face: a third of every
    face 8 cells wide, as on the octagonal bus. Those come back here, the straddler does not
    (its points on the other face leave the plane). At the true motion at 100 m the planar points
    went from 55 to 70 % on the truss and 52 to 67 % on Hubble; on the box the accepted cells
    holding any point of another face went from 0.25 to 2.8 % (100 m; 1.9 % at 50 m), with 0.3 %
    of their points on another face, within the sigmas above of the plane."""
    nb, cell, normal_ref, tilt_var_rad2 = planes.neighbours, planes.cell, planes.normal_ref, planes.tilt_var_rad2
    safe = np.where(nb >= 0, nb, 0)
    rows = np.arange(len(nb))
    cos = np.abs(np.einsum("ni,nki->nk", normal_ref, normal_ref[safe]))
    cos = np.where((nb >= 0) & face[safe], cos, -1.0)
    best = np.argmax(cos, axis=1)
    k_of = safe[rows, best]
    agree = cos > np.cos(normal_tolerance(tilt_var_rad2[:, None], tilt_var_rad2[safe]))
    ok = candidate & agree[rows, best] & (agree.sum(axis=1) >= BESIDE_MIN_NEIGHBOURS)
    pts = np.flatnonzero(ok[cell])
    c = cell[pts]
    z2 = _z2_to_plane(planes, pts, k_of[c])
    worst = np.zeros(len(nb))
    np.maximum.at(worst, c, z2)
    return np.asarray(ok & (worst <= BESIDE_MAX_SIGMAS**2))


def _z2_to_plane(planes: CellPlanes, pts: IntArray, k: IntArray) -> FloatArray:
    """Squared offset of each point ``pts`` from the plane of cell ``k`` (one per point), in
    sigmas: the point's noise along the normal (its own cell's ``var_m2``) plus the plane's, its
    centroid's and its normal's tilt over the in-plane offset."""
    c = planes.cell[pts]
    offset = planes.mapped_m[pts] - planes.mean_m[k]
    d = np.einsum("ni,ni->n", planes.normal_ref[k], offset)
    in_plane2 = np.einsum("ni,ni->n", offset, offset) - d**2
    return np.asarray(
        d**2 / (planes.var_m2[c] + planes.var_m2[k] / planes.count[k] + planes.tilt_var_rad2[k] * in_plane2)
    )


def clear_of_other_faces(planes: CellPlanes, cells: NDArray[np.bool_], other: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """The ``cells`` none of whose points (``mapped_m`` at ``T``) lies within
    ``BESIDE_MAX_SIGMAS`` of the plane of a neighbour in ``other`` that faces another way (normals
    apart by more than :func:`normal_tolerance`), its sigma as in :func:`beside_face`.

    A cell across an edge passes the face tests when the other face's points in it are few and
    lie within the noise of its plane (a panel's 4 cm edge at 2 range sigmas, the bus's 45 deg
    corners): they lean its normal and centroid the same way in every frame, and that bias, not
    noise, put the truss's precession rate 3-5 sigmas off (docs/linescan-rounds.md). One statistic of
    its own points cannot see them (5-8 % of the points, within 2 sigmas). Where a cell inside
    the other face lies beside it, though, those points and the cell's own points near the edge
    lie on both planes: a cell reaching into that band may hold the other face's points, and is
    left out (at the true motion, 17-18 % of the truss's straddlers for 2 % of its other planar
    cells). A cell wholly on one face but reaching into the band is lost with it (the band is a few
    sigmas over the sine of the edge's angle wide). ``other``: the cells inside a face; a cell
    across an edge, half on either face, may be flat with its plane halfway between theirs, and
    taking it as another face left out the cells beside every edge of the folded wall (72 -> 61 %
    of its points).

    Also tried, and left out: the hand-over's test by the line of sight (:func:`.handover.line_sees`) in
    place of the points' offsets, leaving a cell out only when a point's line does not clearly
    see its own plane. It kept 0.3 % more cells (box and truss at 50 m, at the true motion) and
    was a little worse in the whole fit: RMS error / bound +0.03 on the dish-boom, the long
    array and the truss, seeds 0-9 (docs/linescan-rounds.md, twelfth round)."""
    neighbours, cell = planes.neighbours, planes.cell
    normal_ref, tilt_var_rad2 = planes.normal_ref, planes.tilt_var_rad2
    safe = np.where(neighbours >= 0, neighbours, 0)
    cos = np.abs(np.einsum("ni,nki->nk", normal_ref, normal_ref[safe]))
    tolerance = normal_tolerance(tilt_var_rad2[:, None], tilt_var_rad2[safe])
    apart = cells[:, None] & (neighbours >= 0) & other[safe] & (cos <= np.cos(tolerance))
    near = np.zeros(len(neighbours), dtype=bool)
    for j in range(neighbours.shape[1]):
        pts = np.flatnonzero(apart[cell, j])
        c = cell[pts]
        near[c[_z2_to_plane(planes, pts, safe[c, j]) <= BESIDE_MAX_SIGMAS**2]] = True
    return np.asarray(cells & ~near)


def clear_of_outlines(
    neighbours: IntArray, count: FloatArray, interior: NDArray[np.bool_], cells: NDArray[np.bool_]
) -> NDArray[np.bool_]:
    """The ``cells`` beside no cell of the silhouette or an occlusion border (not ``interior``)
    holding fewer than ``OUTLINE_MIN_SHARE`` of their own points.

    A face's outline then runs near the side the two cells share, and what lies just past it
    (a panel's 4 cm edge, another face of the bus seen at a grazing angle) reaches into the cell,
    within the noise of its plane, where no neighbour's plane can tell it apart (the other face
    makes no flat cell of its own there, see :func:`clear_of_other_faces`). Beside a neighbour
    on the outline that holds more points, the outline and what lies past it fall in that
    neighbour. At the true motion: 25-33 % of the truss's straddlers for 4-6 % of its other
    planar cells (at half a cell's points, 37-46 % for 9-12 %)."""
    side = neighbours[:, list(SIDE_NEIGHBOURS)]
    safe = np.where(side >= 0, side, 0)
    sliver = (side >= 0) & ~interior[safe] & (count[safe] < OUTLINE_MIN_SHARE * count[:, None])
    return np.asarray(cells & ~np.any(sliver, axis=1))
