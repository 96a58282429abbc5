"""Where thin members (booms, truss wires) lie: lines at ``T`` through the hits no planar surfel holds.

A member a cell or two wide makes no planar surfel: its cells are strips with no plane to fit,
on the silhouette. Members are found at the current motion (:func:`find_members`): strips (a
cell's free points, split where their ranges jump, along one direction) with no planar cell
beside them, joined across frames where they lie on one line at ``T``; a group counts as a member
when at least ``MIN_FRAMES`` frames see it and it is ``MIN_LENGTH_SURFELS`` surfels long. Each
member's line claims the free hits near it; what those hits say about the motion is
:mod:`.beams`'.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..._typing import FloatArray, IntArray
from ..sensor import SensorNoise
from .data import MAX_RANGE_STEP, DenseData
from .mapping import LineMapping
from .surfels import Surfels

# A strip: the scatter (less the range noise along the sight) has a largest eigenvalue this many
# times the middle one, from at least this many points.
LINE_RATIO = 3.0
MIN_LINE_POINTS = 4
# Strips of two frames are one member's when their centres at T lie within LINK_SURFELS surfels,
# their directions within LINK_MAX_ANGLE and each centre within LINK_SURFELS_ACROSS surfels of the
# other's line.
LINK_SURFELS = 2.5
LINK_MAX_ANGLE = np.radians(15.0)
LINK_SURFELS_ACROSS = 0.5
# A member's strips: centres within MEMBER_SURFELS_ACROSS surfels of its line, directions within
# MEMBER_MAX_ANGLE; the best of MAX_SEEDS strips seeds each line, until MAX_IDLE_ROUNDS rounds in a
# row find none.
MEMBER_SURFELS_ACROSS = 0.5
MEMBER_MAX_ANGLE = np.radians(30.0)
MAX_SEEDS = 40
MAX_IDLE_ROUNDS = 5
GROW_REACH_SURFELS = (2.0, 4.0, 8.0, 16.0, 32.0, 64.0)
# Lines times strips grown side by side at most (the groups of strips hold a few hundred).
MAX_SUPPORT_ENTRIES = 1_000_000
# A member: seen in this many frames, this long.
MIN_FRAMES = 3
MIN_LENGTH_SURFELS = 4.0
# A cell's free points are split into pieces where their ranges jump by more than this many range
# sigmas or this share of a surfel, whichever is more.
PIECE_GAP_SIGMAS = 5.0
PIECE_GAP_SURFELS = 0.5
# Members on one line (parallel within MERGE_MAX_ANGLE, each centre within MERGE_SURFELS surfels of
# the other's line) are one.
MERGE_MAX_ANGLE = np.radians(10.0)
MERGE_SURFELS = 1.0
# A line with a planar surfel within BESIDE_PLANE_SURFELS surfels along more than MAX_BESIDE_PLANE of
# its length is a plate's rim, not a member.
BESIDE_PLANE_SURFELS = 1.5
MAX_BESIDE_PLANE = 0.6
# A member's line claims every free hit within this many surfels of it.
CLAIM_SURFELS = 1.0


@dataclass(frozen=True)
class Members:
    """The members found at one motion: ``point_member`` ``(n,)`` each point's member (``-1`` for
    none), ``count`` members; every point mapped to ``T``, ``y_t`` ``(n, 3)``, and its unit line of
    sight there, ``sight_t`` ``(n, 3)`` (rows of points in a planar surfel left zero)."""

    point_member: IntArray
    count: int
    y_t: FloatArray
    sight_t: FloatArray


def find_members(data: DenseData, mapping: LineMapping, surf: Surfels, noise: SensorNoise) -> Members:
    """The members at the motion ``mapping`` (module docstring), from the points in no planar
    surfel of ``surf``, and the free hits each one's line claims."""
    free = ~surf.planar[surf.point_cell]
    # Only the free points are read below: the others' rows stay zero.
    idx = np.flatnonzero(free)
    y_t, sight_t = np.zeros((len(free), 3)), np.zeros((len(free), 3))
    y_t[idx] = mapping.apply(data.xyz_m[idx], data.line[idx])
    sight_t[idx] = sights(data, mapping, idx)
    piece = range_pieces(data, free, max(PIECE_GAP_SIGMAS * noise.range_sigma_m, PIECE_GAP_SURFELS * data.surfel_m))
    strip, direction, centre, frame = strip_pieces(data, y_t, sight_t, surf.planar, piece, noise)
    pieces = np.flatnonzero(strip)
    group = _linked_groups(centre[pieces], direction[pieces], data.surfel_m)
    count = np.bincount(piece[piece >= 0], minlength=len(strip)).astype(float)
    across_m = MEMBER_SURFELS_ACROSS * data.surfel_m
    members: list[IntArray] = []
    for in_group in by_label(group, int(group.max(initial=-1)) + 1):
        mine = pieces[in_group]
        if len(np.unique(frame[mine])) < MIN_FRAMES:
            continue
        members += [
            mine[on]
            for on in _members(centre[mine], direction[mine], count[mine], frame[mine], data.surfel_m, across_m)
        ]
    lines = []
    for on in _merged(members, centre, direction, count, MERGE_SURFELS * data.surfel_m):
        c, d = fit_line(centre[on], count[on])
        along = (centre[on] - c) @ d
        lines.append((c, d, along.min() - data.surfel_m, along.max() + data.surfel_m))
    lines = _clear_of_planes(lines, surf, mapping, data.surfel_m)
    # Every free hit near a member's line is its (the pieces too short or too mixed for a strip
    # of their own too), the nearest member's where two are near.
    point_member = _claimed(y_t, free, lines, CLAIM_SURFELS * data.surfel_m)
    return Members(point_member, len(lines), y_t, sight_t)


def _moments(cell: IntArray, y: FloatArray, m: int) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Per cell: count ``(m,)``, sum ``(m, 3)``, sum of outer products ``(m, 3, 3)`` of the rows ``y``."""
    count = np.bincount(cell, minlength=m).astype(float)
    s1 = np.stack([np.bincount(cell, y[:, i], minlength=m) for i in range(3)], axis=1).astype(float)
    s2 = np.empty((m, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            s2[:, i, j] = s2[:, j, i] = np.bincount(cell, y[:, i] * y[:, j], minlength=m)
    return count, s1, s2


def _line_shape(
    count: FloatArray,
    s1: FloatArray,
    s2: FloatArray,
    sight_t: FloatArray,
    range_var_m2: float,
    *,
    ratio: float = LINE_RATIO,
    min_points: int = MIN_LINE_POINTS,
) -> tuple[NDArray[np.bool_], FloatArray]:
    """Whether the moments' scatter, less the range noise along ``sight_t`` (unit, at ``T``), has one
    dominant direction (its variance ``ratio`` times the next, from ``min_points``), and that
    direction ``(m, 3)``."""
    safe = np.maximum(count, 1)
    mean = s1 / safe[:, None]
    cov = s2 / safe[:, None, None] - mean[:, :, None] * mean[:, None, :]
    cov -= range_var_m2 * sight_t[:, :, None] * sight_t[:, None, :]
    w, V = np.linalg.eigh(cov)
    line = (count >= min_points) & (np.maximum(w[:, 1], 0.0) * ratio <= w[:, 2])
    return np.asarray(line), np.asarray(V[:, :, 2])


def range_pieces(data: DenseData, free: NDArray[np.bool_], gap_m: float) -> IntArray:
    """Each free point's piece ``(n,)`` (``-1`` for the others): its cell's free points split where
    their ranges, in order, jump by more than ``gap_m``. A cell of the view holds whatever lies
    along its rays: the front and back members of a truss, a wire before a panel."""
    idx = np.flatnonzero(free)
    rho = data.range_m[idx]
    order = np.lexsort((rho, data.cell[idx]))
    cell, rho = data.cell[idx][order], rho[order]
    new = np.ones(len(idx), dtype=bool)
    new[1:] = (cell[1:] != cell[:-1]) | (np.diff(rho) > gap_m)
    piece = np.full(len(free), -1, dtype=np.int64)
    piece[idx[order]] = np.cumsum(new) - 1
    return piece


def strip_pieces(
    data: DenseData,
    y_t: FloatArray,
    sight_t: FloatArray,
    planar: NDArray[np.bool_],
    piece: IntArray,
    noise: SensorNoise,
) -> tuple[NDArray[np.bool_], FloatArray, FloatArray, IntArray]:
    """Pieces (:func:`range_pieces`) whose points form a strip, with no planar cell beside them at
    a similar range (a plate's strip along its outline has its plate there; a member has none):
    the mask ``(k,)``, each piece's direction ``(k, 3)`` and centre at ``T`` ``(k, 3)``, and its frame
    ``(k,)``. ``y_t``: every point at ``T``; ``sight_t``: its line of sight at ``T``."""
    k = int(piece.max(initial=-1)) + 1
    on = piece >= 0
    count, s1, s2 = _moments(piece[on], y_t[on], k)
    sight = np.stack([np.bincount(piece[on], sight_t[on, i], minlength=k) for i in range(3)], axis=1).astype(float)
    sight /= np.maximum(np.linalg.norm(sight, axis=1, keepdims=True), 1e-300)
    line, direction = _line_shape(count, s1, s2, sight, noise.range_sigma_m**2)
    # Each piece's cell and range; the cells' ranges (over all their points).
    first = np.zeros(k, dtype=np.int64)
    first[piece[on]] = np.flatnonzero(on)
    cell = data.cell[first]
    rho = np.bincount(piece[on], data.range_m[on], minlength=k) / np.maximum(count, 1)
    cell_rho = data.cell_range_m
    beside_plane = np.zeros(k, dtype=bool)
    for j in range(data.neighbours.shape[1]):
        nb = data.neighbours[cell, j]
        near = (nb >= 0) & (np.abs(cell_rho[np.maximum(nb, 0)] - rho) <= MAX_RANGE_STEP * data.surfel_m)
        beside_plane |= near & planar[np.maximum(nb, 0)]
    strip = line & ~beside_plane & ~planar[cell]
    return np.asarray(strip), direction, np.asarray(s1 / np.maximum(count, 1)[:, None]), data.cell_frame[cell]


def _linked_groups(centre: FloatArray, direction: FloatArray, surfel_m: float) -> IntArray:
    """Group of each strip: strips joined, loosely, where they could lie on one line (``LINK_*``);
    a group may hold several members that meet (a node of a truss), split by :func:`_members`."""
    n = len(centre)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    pairs = cKDTree(centre).query_pairs(LINK_SURFELS * surfel_m, output_type="ndarray")
    a, b = pairs[:, 0], pairs[:, 1]
    aligned = np.abs(np.einsum("ni,ni->n", direction[a], direction[b])) >= np.cos(LINK_MAX_ANGLE)
    gap = centre[b] - centre[a]
    across = LINK_SURFELS_ACROSS * surfel_m
    for d in (direction[a], direction[b]):
        along = np.einsum("ni,ni->n", gap, d)
        aligned &= np.einsum("ni,ni->n", gap, gap) - along**2 <= across**2
    graph = coo_matrix((np.ones(int(aligned.sum())), (a[aligned], b[aligned])), shape=(n, n))
    return np.asarray(connected_components(graph, directed=False)[1], dtype=np.int64)


def _support(
    centre: FloatArray, direction: FloatArray, c: FloatArray, d: FloatArray, across_m: float
) -> tuple[NDArray[np.bool_], FloatArray]:
    """Strips on each line ``c_k + s d_k`` (``c``, ``d``: ``(k, 3)``): centre within ``across_m`` of
    it, direction within ``MEMBER_MAX_ANGLE``, ``(k, n)``; with each strip's offset along it."""
    gap = centre[None, :, :] - c[:, None, :]
    along = np.einsum("kni,ki->kn", gap, d)
    near = np.einsum("kni,kni->kn", gap, gap) - along**2 <= across_m**2
    return np.asarray(near & (np.abs(d @ direction.T) >= np.cos(MEMBER_MAX_ANGLE))), np.asarray(along)


def _grown(
    seeds: IntArray, centre: FloatArray, direction: FloatArray, weight: FloatArray, across_m: float, surfel_m: float
) -> tuple[FloatArray, FloatArray]:
    """The lines ``(k, 3)``, ``(k, 3)`` through strips ``seeds``, grown along themselves: each
    line's strips within a reach that doubles, the line fitted to their centres each time (one
    strip's direction is a few degrees off; over a few metres the centres fix it); a line stops
    growing when fewer than two strips are within its reach."""
    c, d = centre[seeds].copy(), direction[seeds].copy()
    growing = np.ones(len(seeds), dtype=bool)
    for reach in GROW_REACH_SURFELS:
        on, along = _support(centre, direction, c[growing], d[growing], across_m)
        on &= np.abs(along) <= reach * surfel_m
        still = on.sum(axis=1) >= 2
        growing[growing] = still
        if not np.any(still):
            break
        c[growing], d[growing] = fit_lines(centre, np.where(on[still], weight, 0.0))
    return c, d


def _members(
    centre: FloatArray, direction: FloatArray, weight: FloatArray, frame: IntArray, surfel_m: float, across_m: float
) -> list[IntArray]:
    """The lines in one group of strips, best supported first (sequential: the best of up to
    ``MAX_SEEDS`` grown lines, its strips taken out, again): each a list of strip indices seen in
    ``MIN_FRAMES`` frames and at least ``MIN_LENGTH_SURFELS`` surfels long."""
    left = np.arange(len(centre))
    untried = left.copy()
    out: list[IntArray] = []
    rng = np.random.default_rng(0)
    idle = 0  # rounds in a row without a member: a large group of strips that are no members
    while len(left) >= MIN_FRAMES and len(untried) and idle < MAX_IDLE_ROUNDS:
        seeds = untried if len(untried) <= MAX_SEEDS else rng.choice(untried, MAX_SEEDS, replace=False)
        # A seed whose line was a member's, though not the best, is tried again in the next round.
        untried = np.setdiff1d(untried, seeds)
        valid: list[int] = []
        best, best_weight = np.zeros(0, dtype=np.int64), 0.0
        c_left, d_left, w_left = centre[left], direction[left], weight[left]
        # The seeds' lines are grown side by side, as many at once as keep the arrays small.
        per_pass = max(1, MAX_SUPPORT_ENTRIES // len(left))
        for first in range(0, len(seeds), per_pass):
            at = np.searchsorted(left, seeds[first : first + per_pass])
            c, d = _grown(at, c_left, d_left, w_left, across_m, surfel_m)
            support, along = _support(c_left, d_left, c, d, across_m)
            for k in range(len(at)):
                on = left[support[k]]
                long_enough = len(on) and np.ptp(along[k][support[k]]) >= MIN_LENGTH_SURFELS * surfel_m
                if not (long_enough and len(np.unique(frame[on])) >= MIN_FRAMES):
                    continue
                valid.append(int(left[at[k]]))
                if weight[on].sum() > best_weight:
                    best, best_weight = on, float(weight[on].sum())
        idle = 0 if len(best) else idle + 1
        if len(best):
            out.append(best)
            left = np.setdiff1d(left, best)
            untried = np.setdiff1d(np.union1d(untried, valid), best)
    return out


def fit_lines(y: FloatArray, w: FloatArray) -> tuple[FloatArray, FloatArray]:
    """:func:`fit_line` of the rows ``y`` ``(n, 3)`` under each row of weights ``w`` ``(k, n)``:
    centres and directions ``(k, 3)``."""
    c = (w @ y) / w.sum(axis=1, keepdims=True)
    v = y[None, :, :] - c[:, None, :]
    scatter = np.einsum("kn,kni,knj->kij", w, v, v)
    d = np.linalg.eigh(scatter)[1][:, :, 2]
    flip = d[np.arange(len(d)), np.argmax(np.abs(d), axis=1)] < 0
    d[flip] *= -1
    return c, d


def fit_line(y: FloatArray, w: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Weighted centre and direction (largest axis of the weighted scatter) of the rows ``y``."""
    c = (w[:, None] * y).sum(axis=0) / w.sum()
    v = y - c
    scatter = (w[:, None] * v).T @ v
    d = np.linalg.eigh(scatter)[1][:, 2]
    # One sign for the same line, whatever the eigensolver returns (the offsets' signs follow it).
    return c, d if d[np.argmax(np.abs(d))] > 0 else -d


def sights(data: DenseData, mapping: LineMapping, idx: IntArray) -> FloatArray:
    """Unit lines of sight of the points ``idx`` turned to ``T``."""
    xyz = data.xyz_m[idx]
    return mapping.rotate(xyz / data.range_m[idx][:, None], data.line[idx])


def by_label(label: IntArray, n: int) -> list[IntArray]:
    """The indices of each label ``0 .. n-1`` in ``label`` (others, such as ``-1``, left out), in order."""
    order = np.argsort(label, kind="stable")
    starts = np.searchsorted(label[order], np.arange(n + 1))
    return [order[starts[k] : starts[k + 1]] for k in range(n)]


def _merged(
    members: list[IntArray], centre: FloatArray, direction: FloatArray, weight: FloatArray, near_m: float
) -> list[IntArray]:
    """The members' strips, with the members on one line joined: parallel within ``MERGE_MAX_ANGLE``,
    each one's centre within ``near_m`` of the other's line. A boom wider than a strip's scatter comes
    apart in two groups (the faces seen lean its strips to one side, then the other); split between
    two lines, each line's hits would lie on one side of it."""
    lines = [fit_line(centre[on], weight[on]) for on in members]
    parent = list(range(len(members)))

    def root(i: int) -> int:
        while parent[i] != i:
            i = parent[i]
        return i

    for i, (ci, di) in enumerate(lines):
        for j in range(i + 1, len(lines)):
            cj, dj = lines[j]
            if abs(di @ dj) < np.cos(MERGE_MAX_ANGLE):
                continue
            gap = cj - ci
            if all(gap @ gap - (gap @ d) ** 2 <= near_m**2 for d in (di, dj)):
                parent[root(j)] = root(i)
    groups: dict[int, list[IntArray]] = {}
    for i, on in enumerate(members):
        groups.setdefault(root(i), []).append(on)
    return [np.concatenate(g) for g in groups.values()]


def _clear_of_planes(
    lines: list[tuple[FloatArray, FloatArray, float, float]], surf: Surfels, mapping: LineMapping, surfel_m: float
) -> list[tuple[FloatArray, FloatArray, float, float]]:
    """The lines with a planar surfel (of any frame, at ``T``) beside at most ``MAX_BESIDE_PLANE`` of
    their length. A plate's rim seen edge on is a strip too, one-sided: its plate lies beside it in
    the other frames. A member stands free, but where it meets the bus."""
    planar = np.flatnonzero(surf.planar)
    if len(planar) == 0 or not lines:
        return lines
    tree = cKDTree(mapping.apply(surf.anchor_obs[planar], surf.line[planar]))
    out = []
    for c, d, lo, hi in lines:
        steps = np.arange(lo, hi + 1e-9, surfel_m)
        near = tree.query_ball_point(c + steps[:, None] * d, BESIDE_PLANE_SURFELS * surfel_m, return_length=True)
        if np.mean(near > 0) <= MAX_BESIDE_PLANE:
            out.append((c, d, lo, hi))
    return out


def _claimed(
    y_t: FloatArray, free: NDArray[np.bool_], lines: list[tuple[FloatArray, FloatArray, float, float]], radius_m: float
) -> IntArray:
    """Each point's member ``(n,)``: the nearest of the ``lines`` (centre, direction, extent along it)
    within ``radius_m`` of it, for the ``free`` points; ``-1`` for the others."""
    out = np.full(len(y_t), -1, dtype=np.int64)
    idx = np.flatnonzero(free)
    if not lines or len(idx) == 0:
        return out
    # Only the points within reach of some line's segment go into the tree.
    ends = np.array([c + t * d for c, d, lo, hi in lines for t in (lo, hi)])
    reach = radius_m * np.sqrt(1.25) + radius_m
    y = y_t[idx]
    idx = idx[np.all((y >= ends.min(axis=0) - reach) & (y <= ends.max(axis=0) + reach), axis=1)]
    if len(idx) == 0:
        return out
    best = np.full(len(y_t), np.inf)
    tree = cKDTree(y_t[idx])
    for k, (c, d, lo, hi) in enumerate(lines):
        # Balls along the segment, radius_m apart, cover its cylinder.
        steps = np.arange(lo, hi + radius_m, radius_m)
        balls = tree.query_ball_point(c + steps[:, None] * d, radius_m * np.sqrt(1.25))
        near = idx[np.unique(np.concatenate([np.asarray(b, dtype=np.int64) for b in balls]))]
        v = y_t[near] - c
        along = v @ d
        dist2 = np.einsum("ni,ni->n", v, v) - along**2
        ok = (along >= lo) & (along <= hi) & (dist2 <= radius_m**2) & (dist2 < best[near])
        best[near[ok]] = dist2[ok]
        out[near[ok]] = k
    return out
