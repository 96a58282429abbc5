"""Thin members (booms, truss wires) fitted as lines: hits that no planar surfel can hold.

A member a cell or two wide makes no planar surfel: its cells are strips with no plane to fit,
on the silhouette. Yet its hits lie far from the centre, where a turn moves them most: on the
wire truss at 100 m they are a tenth of the hits and, as lines, would bring the bound of the
hits the fit uses from twice the bound of all hits to it (``bench/linescan/line_potential.py``).

At ``T`` the hits of one member, from every frame, lie along one line ``c + s d``. A hit ``p`` of
a line at ``tau``, mapped to ``T`` by the motion ``x``, gives the offset

    r = e . (M(p, tau; x) - c),    e = d x u / |d x u|,
    var r = max(w_f, (s_a rho)^2)

across the line and across its line of sight ``u`` (turned to ``T``): ``w_f`` is the spread of
the member's hits across it in that frame (its section as the pixels see it, with the sensor's
angle noise; the member's own spread where a frame has few hits), at least the angle noise
``(s_a rho)^2``, and at least the hits per segment (a surfel of the member) times the scatter of
the segments' mean offsets: which pixels hit a wire two pixels wide changes slowly along it, so
neighbouring hits err together and hold no more than their mean does.

Along the sight, ``a = d x e`` (towards the sensor), the hits lie on the faces the sensor sees,
ahead of the axis by ``b``, about half the member's width:

    r_a = a . (M(p, tau; x) - c) - b,    var r_a = max(v_f, s_r^2),

``v_f`` the hits' spread along the sight in that frame (range noise and the section's depth),
floored as above. ``b`` is the member's own (``pi w / 8`` for a round section of width ``w``);
on a square section it changes as the view turns about the axis (0.35-0.5 of the width), an
error common to a frame's hits, ``DEPTH_WOBBLE`` times their spread across RMS: those rows are
whitened for it (:func:`_shrinks`). The line and ``b`` are nuisances (two offsets, two tilts, the
depth), eliminated per member: the rows are projected off their five directions (variable
projection, Kaufman's Jacobian).

Members, and the free hits each one claims, are found at the current motion
(:func:`.members.find_members`); here a member keeps the hits that lie on its line (within
``OUTLIER_SIGMAS`` of it, not seen end on) when it is still seen in ``MIN_FRAMES`` frames over
``MIN_LENGTH_SURFELS`` surfels and they keep within ``MAX_SPREAD_M`` of the line.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix

from ..._typing import FloatArray, IntArray
from ..sensor import SensorNoise, perpendiculars
from .data import DenseData
from .mapping import LineMapping
from .members import MIN_FRAMES, MIN_LENGTH_SURFELS, MIN_LINE_POINTS, by_label, find_members, fit_line, sights
from .surfels import Surfels

# A member's hits keep within this RMS distance of its line (m).
MAX_SPREAD_M = 0.08
# A hit whose sight runs within this angle of the member says little across it (seen end on).
MIN_SIGHT_ANGLE = np.radians(30.0)
# Segments (a surfel long) of one frame's hits of a member needed to measure how their offsets err together.
MIN_SEGMENTS = 4
# A hit this many robust sigmas off its member's line is another part's (a node, a crossing member).
OUTLIER_SIGMAS = 3.0
# How far the faces seen of a square section lie ahead of its axis changes as the view turns about
# it (0.35-0.5 of its width): by this many times the spread of its hits across it, RMS, common to a
# frame's hits (measured at the true motion: 0.4-1.0 cm on the 10 cm boom, 0.5-0.6 cm on the 12 cm).
DEPTH_WOBBLE = 0.15


@dataclass(frozen=True)
class Beams:
    """The hits on members, grouped by member: ``point`` ``(n,)`` indices into the data's points,
    member by member; ``var_m2`` ``(n,)`` each offset's variance across the line (before the
    common scale); ``bounds`` ``(members + 1,)`` where each member's hits start in ``point``;
    ``depth_var_m2`` ``(n,)`` the variance of each offset along the sight, and ``depth_shrink``
    ``(n,)`` the share of its member's mean in its frame taken off each of them (:func:`_shrinks`)."""

    point: IntArray
    var_m2: FloatArray
    bounds: IntArray
    depth_var_m2: FloatArray
    depth_shrink: FloatArray

    @property
    def members(self) -> int:
        return len(self.bounds) - 1

    @property
    def row_var_m2(self) -> FloatArray:
        """The variance of each row of :func:`beam_rows`: across the lines, then along the sights."""
        return np.concatenate([self.var_m2, self.depth_var_m2])

    @staticmethod
    def none() -> Beams:
        empty = np.zeros(0, dtype=np.int64)
        return Beams(empty, np.zeros(0), np.zeros(1, dtype=np.int64), np.zeros(0), np.zeros(0))


def find_beams(data: DenseData, mapping: LineMapping, surf: Surfels, noise: SensorNoise) -> Beams:
    """The members at the motion ``mapping`` (:func:`.members.find_members`), each with the hits
    that lie on its line and their variances (module docstring)."""
    found = find_members(data, mapping, surf, noise)
    hits = []
    for claimed in by_label(found.point_member, found.count):
        one = _member_hits(data, claimed, found.y_t, found.sight_t, noise)
        if one is not None:
            hits.append(one)
    if not hits:
        return Beams.none()
    point, lateral, ahead, shrink = (np.concatenate(parts) for parts in zip(*hits, strict=True))
    bounds = np.concatenate([[0], np.cumsum([len(one[0]) for one in hits])]).astype(np.int64)
    return Beams(point, lateral, bounds, ahead, shrink)


def _member_hits(
    data: DenseData, idx: IntArray, y_t: FloatArray, sight_t: FloatArray, noise: SensorNoise
) -> tuple[IntArray, FloatArray, FloatArray, FloatArray] | None:
    """The hits ``idx`` of one member that lie on its line (not seen end on, not another part's),
    the variances of each one's offsets across the line and along the sight, and the latter's
    shrinks (:func:`_shrinks`); None when they are no member (too
    few frames, too short, or spread wider than ``MAX_SPREAD_M``)."""
    if len(np.unique(data.frame[idx])) < MIN_FRAMES:
        return None
    range_var_m2 = noise.range_sigma_m**2
    lateral_var = (noise.angle_sigma_rad * data.range_m[idx]) ** 2
    keep = np.ones(len(idx), dtype=bool)
    for _ in range(2):
        # The line, then the hits off it (a node, a crossing member), twice (beam_rows fits it anew).
        c, d = fit_line(y_t[idx[keep]], np.ones(int(keep.sum())))
        along = (y_t[idx] - c) @ d
        off = y_t[idx] - c - along[:, None] * d
        e = np.cross(d, sight_t[idx])
        sin = np.linalg.norm(e, axis=1)
        e /= np.maximum(sin, 1e-12)[:, None]
        r = np.einsum("ni,ni->n", e, off)
        ahead = np.einsum("ni,ni->n", np.cross(d, e), off)
        keep = sin >= np.sin(MIN_SIGHT_ANGLE)
        if not np.any(keep):
            return None
        scale = max(1.4826 * float(np.median(np.abs(r[keep]))), float(np.sqrt(np.median(lateral_var))))
        ahead_mid = float(np.median(ahead[keep]))
        ahead_scale = max(_robust_sigma(ahead[keep]), float(np.sqrt(range_var_m2)))
        keep &= np.abs(r) <= OUTLIER_SIGMAS * scale
        keep &= np.abs(ahead - ahead_mid) <= OUTLIER_SIGMAS * ahead_scale
    frame = data.frame[idx]
    if len(np.unique(frame[keep])) < MIN_FRAMES or np.ptp(along[keep]) < MIN_LENGTH_SURFELS * data.surfel_m:
        return None
    if np.sqrt(np.mean(np.sum(off[keep] ** 2, axis=1))) > MAX_SPREAD_M:
        return None
    idx, frame, lateral_var = idx[keep], frame[keep], lateral_var[keep]
    segment = np.floor(along[keep] / data.surfel_m).astype(np.int64)
    # The member's section as the pixels see it, per frame: the spread of its hits across it and
    # along the sight, at least the sensor's noise.
    lateral = np.maximum(_frame_spread(r[keep], frame, segment, scale**2), lateral_var)
    ahead_var = np.maximum(_frame_spread(ahead[keep], frame, segment, ahead_scale**2), range_var_m2)
    across = float(np.median([_robust_sigma(r[keep][frame == f]) for f in np.unique(frame)]))
    return idx, lateral, ahead_var, _shrinks(frame, ahead_var, (DEPTH_WOBBLE * across) ** 2)


def _shrinks(frame: IntArray, var_m2: FloatArray, common_m2: float) -> FloatArray:
    """Per hit, the share ``c`` of its frame's mean to take off rows of variance ``var_m2`` (one per
    frame) that share an error of variance ``common_m2`` within a frame: with ``n`` hits,
    ``r - c mean(r)``, ``c = 1 - sqrt(v / (v + n common))``, are independent of variance ``v`` (the
    inverse square root of ``v I + common 1 1^T``), so the frame's mean weighs as one measurement of
    variance ``v / n + common`` and the hits' offsets from it keep their own weight."""
    _, inverse, n = np.unique(frame, return_inverse=True, return_counts=True)
    return np.asarray(1.0 - np.sqrt(var_m2 / (var_m2 + n[inverse] * common_m2)))


def _robust_sigma(r: FloatArray) -> float:
    """The spread of ``r`` from its median absolute deviation."""
    return 1.4826 * float(np.median(np.abs(r - np.median(r))))


def _frame_spread(r: FloatArray, frame: IntArray, segment: IntArray, fallback_m2: float) -> FloatArray:
    """Per hit, the spread of the offsets ``r`` of its frame's hits (``fallback_m2`` for a frame
    with few), at least what the hits of a segment hold together (:func:`_correlated`)."""
    spread = np.full(len(r), fallback_m2)
    for f in np.unique(frame):
        on = frame == f
        if on.sum() >= MIN_LINE_POINTS:
            spread[on] = max(_robust_sigma(r[on]) ** 2, _correlated(r[on], segment[on]))
    return spread


def _correlated(r: FloatArray, segment: IntArray) -> float:
    """Per hit, the variance that weighs a segment's hits (a surfel of the member long) as what their
    mean holds: the hits' offsets err together along a member (which pixels hit a wire two pixels
    wide changes slowly along it), so ``n`` of them hold no more than their mean's scatter from
    segment to segment, ``n var(segment means)``; 0 with fewer than ``MIN_SEGMENTS`` segments."""
    _, inverse, n = np.unique(segment, return_inverse=True, return_counts=True)
    full = n >= 2
    if full.sum() < MIN_SEGMENTS:
        return 0.0
    means = np.bincount(inverse, r) / n
    return float(np.mean(n[full]) * np.var(means[full], ddof=1))


def beam_rows(
    beams: Beams, data: DenseData, mapping: LineMapping, *, jacobian: bool = True
) -> tuple[FloatArray, FloatArray | None, FloatArray]:
    """The offsets ``r`` (m) at the motion ``mapping``, one row per hit across its member's line and
    its sight, then one along its sight, with each member's line fitted to its
    hits at ``T`` and projected out, and the depth its faces seen lie ahead of the line too; their
    Jacobian ``(rows, free)`` (Kaufman's projection; the rows' directions held), when asked; and
    the hits at ``T`` ``(n, 3)``. Rows in the order of :attr:`Beams.row_var_m2`."""
    n = len(beams.point)
    xyz, line = data.xyz_m[beams.point], data.line[beams.point]
    y = mapping.apply(xyz, line)
    u = sights(data, mapping, beams.point)
    w = 1.0 / beams.row_var_m2
    direction = np.empty((2 * n, 3))
    J_line = np.zeros((2 * n, 5))
    r = np.empty(2 * n)
    rows = []
    for k in range(beams.members):
        s = np.arange(beams.bounds[k], beams.bounds[k + 1])
        c, d = fit_line(y[s], w[s])
        across = np.cross(d, u[s])
        across /= np.maximum(np.linalg.norm(across, axis=1, keepdims=True), 1e-12)
        E = np.stack(perpendiculars(d[None, :]), axis=1)[0]  # (2, 3): the line's offsets and tilts
        along = (y[s] - c) @ d
        # Across the line and the sight; then ahead of the line, towards the sensor.
        for block, v in enumerate([across, np.cross(d, across)]):
            at = block * n + s
            ve = v @ E.T
            J_line[at, :4] = -np.concatenate([ve, along[:, None] * ve], axis=1)
            direction[at], r[at] = v, np.einsum("ni,ni->n", v, y[s] - c)
        J_line[n + s, 4] = -1.0  # the depth of the faces seen ahead of the line
        rows.append(np.concatenate([s, n + s]))
    J_x = None
    if jacobian:
        J_x = mapping.normal_derivative(direction, np.concatenate([xyz, xyz]), np.concatenate([line, line]))
    # The depth rows of a member in a frame share the section's wobble: whitened (_shrinks).
    shrink = _frame_shrink(beams, data)
    r[n:] = shrink(r[n:])
    J_line[n:] = shrink(J_line[n:])
    if J_x is not None:
        J_x[n:] = shrink(J_x[n:])
    for at in rows:
        if J_x is None:
            (r[at],) = without_nuisances(J_line[at], w[at], r[at])
        else:
            r[at], J_x[at] = without_nuisances(J_line[at], w[at], r[at], J_x[at])
    return r, J_x, y


def without_nuisances(J_nuisance: FloatArray, w: FloatArray, *rows: FloatArray) -> tuple[FloatArray, ...]:
    """Each of ``rows`` (residuals ``(k,)`` or derivatives ``(k, p)``) less the share the
    nuisances explain, ``a - J_n (J_n^T W J_n)^+ J_n^T W a`` (Kaufman's projection; ``J_nuisance``
    ``(k, q)``, ``w`` the rows' weights ``(k,)``): what is left depends on the motion alone."""
    Jw = J_nuisance * w[:, None]
    info = np.linalg.pinv(Jw.T @ J_nuisance, rcond=1e-10, hermitian=True)
    return tuple(a - J_nuisance @ (info @ (Jw.T @ a)) for a in rows)


def _frame_shrink(beams: Beams, data: DenseData) -> Callable[[FloatArray], FloatArray]:
    """``a -> a - c mean(a)``, the mean over each member's hits in one frame and ``c`` the hits'
    ``depth_shrink``, for arrays of one row per hit."""
    member = np.repeat(np.arange(beams.members), np.diff(beams.bounds))
    _, group, count = np.unique(
        member * (int(data.frame.max()) + 1) + data.frame[beams.point], return_inverse=True, return_counts=True
    )
    S = coo_matrix((np.ones(len(group)), (group, np.arange(len(group)))), shape=(len(count), len(group))).tocsr()
    c = beams.depth_shrink

    def shrink(a: FloatArray) -> FloatArray:
        mean = (S @ a) / (count[:, None] if a.ndim == 2 else count)
        return a - (c[:, None] if a.ndim == 2 else c) * mean[group]

    return shrink
