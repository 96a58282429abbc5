"""Hits seen at grazing incidence that no planar surfel holds, against the other frames' surfels.

At grazing incidence a face's cells run far along the sight: neighbouring cells lie a cell's
width times ``tan(incidence)`` apart in range, and the view's interior test takes them for an
occlusion border, so their hits stay out of the planar surfels. Yet such a hit's noise along
the face's normal is the angle noise (``s_a rho``, 0.9 cm at 50 m), not the range noise (2 cm),
and they lie on the far edges of faces, where a turn moves them most: beside the hits the
surfels use they held a third to nine tenths of what the left-out hits could add to the
bound (``bench/linescan/line_potential.py``).

Each hit ``x`` of frame ``f`` outside every planar surfel (and off every thin member), in a cell
none of whose points the surfel build handed to a planar neighbour, is matched, in every other
frame ``b``, to the nearest planar surfel ``a_t`` of ``b`` within one surfel size at ``T``, and kept
when the sight meets that plane at grazing incidence and

    r = n_t . (M(x) - a_t),   |r| <= 3 sqrt(var_x + v_t / N_t),   in-plane offset <= 0.75 surfel

with ``var_x`` the hit's sensor variance along ``n_t`` (:func:`.surfels.normal_variance`) and the
plane facing the hit's sensor (only hits whose own cell looks grazing are tried:
``CELL_MAX_COS``). The hits of one cell matched to one target are one residual, a pseudo-surfel
at their mean ``g`` (attached, as a surfel is, to the line of their mean time):

    r = n_t . (M(g) - a_t),   var = var_g / k + v_t / N_t + d^2 v_nt

with ``var_g`` the sensor variance along ``n_t`` at ``g``, ``k`` its hits and ``d`` its in-plane
offset from the target. Only grazing hits: the other left-out hits, matched so, sit 1.3-2.6 of
their own sigmas off the truth (edges, and the build's hand-over, which leaves out the points on
the far side of a face); the grazing ones 0.8-1.8, and beside the pairs they lowered the error
on five shapes of six (``bench/linescan/hit_pairs.py --grazing 0.3``). Whole cells only: the
hits the hand-over leaves behind are what its selection left, and with them the fit's centre
moved by 0.37-0.78 mm between all frames and the first ones alone, 2.9-4.1 of the validation's
sigmas (the telescope at 50 m seed 8, which then failed the check; without them 0.30-0.64 mm,
2.2-3.1 sigmas).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..._typing import FloatArray, IntArray
from ..sensor import SensorNoise
from .data import DenseData, cell_lines
from .mapping import LineMapping
from .surfels import Surfels, normal_variance

# Grazing: the sight meets the target's plane with |cos(incidence)| below this (73 deg).
MAX_COS_INCIDENCE = 0.3
# Only the hits whose own cell's normal is at least this grazing are matched at all (the cell's
# normal is noisier than the target's; at the truth, on the box and Hubble at 50 m seed 0, this
# kept 98 % of the hits matched without it and halved the search: a script, not kept).
CELL_MAX_COS = 0.5
MAX_INPLANE_SURFELS = 0.75
GATE_SIGMAS = 3.0


@dataclass(frozen=True)
class Grazing:
    """The groups (one per source cell and target surfel): their hits' mean in the sensor frame
    at the line of their mean time ``(g, 3)``, that line ``(g,)``, their hit count ``(g,)``, target
    planar surfel ``(g,)`` and source cell ``(g,)``; and the distinct hits they hold (indices into
    the data's points)."""

    xyz_obs: FloatArray
    line: IntArray
    count: FloatArray
    target: IntArray
    cell: IntArray
    hit: IntArray

    @property
    def groups(self) -> int:
        return len(self.target)

    @property
    def hits(self) -> int:
        return len(self.hit)

    @staticmethod
    def none() -> Grazing:
        empty = np.zeros(0, dtype=np.int64)
        return Grazing(np.zeros((0, 3)), empty, np.zeros(0), empty, empty, empty)


def find_grazing(
    data: DenseData, mapping: LineMapping, surf: Surfels, noise: SensorNoise, *, exclude: IntArray | None = None
) -> Grazing:
    """The grazing groups at ``mapping`` (see the module). exclude: hits to leave out (the thin
    members' own)."""
    h_all = grazing_candidates(data, surf, exclude=exclude)
    if len(h_all) == 0 or not np.any(surf.planar):
        return Grazing.none()
    hit, target = match_to_surfels(data, mapping, surf, noise, h_all, max_cos=MAX_COS_INCIDENCE)
    return group_hits(data, mapping, surf, hit, target)


def grazing_candidates(data: DenseData, surf: Surfels, *, exclude: IntArray | None = None) -> IntArray:
    """The hits tried (indices into the data's points): outside every planar surfel and off
    ``exclude``, in cells the build handed none of to a planar neighbour, whose own normal looks
    grazing (see the module)."""
    free = ~surf.planar[surf.point_cell]
    # Whole cells only: where the build handed some of a cell's points to a planar neighbour
    # (handover.assign_to_faces), the rest is what that selection left, not a fair sample.
    handed = np.zeros(len(surf.planar), dtype=bool)
    handed[data.cell[surf.point_cell != data.cell]] = True
    free &= ~handed[data.cell]
    if exclude is not None:
        free[exclude] = False
    # Only hits whose own cell is seen at grazing incidence: the search over every other frame
    # costs a query per hit and frame.
    h_free = np.flatnonzero(free)
    xyz = data.xyz_m[h_free]
    own_cos = np.abs(np.einsum("ni,ni->n", xyz, surf.normal_obs[data.cell[h_free]]))
    return h_free[own_cos < CELL_MAX_COS * np.linalg.norm(xyz, axis=1)]


def group_hits(data: DenseData, mapping: LineMapping, surf: Surfels, hit: IntArray, target: IntArray) -> Grazing:
    """The matched hits ``(k,)`` (indices into the data's points) and their target surfels ``(k,)``
    as groups, one per source cell and target: its hits' mean at ``T``, attached to their mean
    line (see the module)."""
    if len(hit) == 0:
        return Grazing.none()
    _, first, group = np.unique(data.cell[hit] * len(surf.planar) + target, return_index=True, return_inverse=True)
    g = len(first)
    count, line = cell_lines(data.tau_s, data.line[hit], group, g)
    mapped = mapping.apply(data.xyz_m[hit], data.line[hit])
    mean_T = np.stack([np.bincount(group, mapped[:, i], minlength=g) for i in range(3)], axis=1) / count[:, None]
    xyz_obs = mapping.center + np.einsum("nji,nj->ni", mapping.Rt[line], mean_T - mapping.center)
    return Grazing(xyz_obs, line, count, target[first], data.cell[hit[first]], np.unique(hit))


def match_to_surfels(
    data: DenseData,
    mapping: LineMapping,
    surf: Surfels,
    noise: SensorNoise,
    hits: IntArray,
    *,
    max_cos: float | None = MAX_COS_INCIDENCE,
) -> tuple[IntArray, IntArray]:
    """Each of ``hits`` (indices into the data's points) matched, in every other frame, to the
    nearest planar surfel within a surfel size at ``T``, kept when that plane faces the hit's
    sensor (with ``|cos(incidence)|`` under ``max_cos``; None: at any incidence), the hit lies
    within ``MAX_INPLANE_SURFELS`` of its anchor along the plane and within ``GATE_SIGMAS`` of it
    across: ``(k,)`` hits and ``(k,)`` their target surfels, a hit once per frame it matched in."""
    x_ref, sensor_ref, anchor_ref, normal_ref = at_reference(data, mapping, surf, hits)
    found, targets = [np.zeros(0, dtype=np.int64)], [np.zeros(0, dtype=np.int64)]
    for sel, in_b in other_frames(data, surf, hits):
        dist, nn = cKDTree(anchor_ref[in_b]).query(x_ref[sel], k=1, distance_upper_bound=data.surfel_m, workers=-1)
        ok = np.isfinite(dist)
        sel, t = sel[ok], in_b[nn[ok]]
        n = normal_ref[t]
        d = x_ref[sel] - anchor_ref[t]
        r = np.einsum("ni,ni->n", n, d)
        sight = sensor_ref[sel] - x_ref[sel]
        cos = np.einsum("ni,ni->n", n, sight) / np.maximum(np.linalg.norm(sight, axis=1), 1e-300)
        h = hits[sel]
        var_x = normal_variance(noise, data.xyz_m[h], np.einsum("nji,nj->ni", mapping.Rt[data.line[h]], n))
        keep = (
            (cos > 0)
            & (np.einsum("ni,ni->n", d, d) - r**2 <= (MAX_INPLANE_SURFELS * data.surfel_m) ** 2)
            & (r**2 <= GATE_SIGMAS**2 * (var_x + surf.var_m2[t] / surf.count[t]))
        )
        if max_cos is not None:
            keep &= cos < max_cos
        found.append(h[keep])
        targets.append(t[keep])
    return np.concatenate(found), np.concatenate(targets)


def at_reference(
    data: DenseData, mapping: LineMapping, surf: Surfels, hits: IntArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """At ``T``: the ``hits`` ``(k, 3)``, their sensor ``(k, 3)``, every surfel's anchor ``(m, 3)``
    and its unit normal ``(m, 3)`` (m)."""
    x_ref = mapping.apply(data.xyz_m[hits], data.line[hits])
    sensor_ref = mapping.apply(np.zeros((len(hits), 3)), data.line[hits])
    return x_ref, sensor_ref, mapping.apply(surf.anchor_obs, surf.line), mapping.rotate(surf.normal_obs, surf.line)


def other_frames(data: DenseData, surf: Surfels, hits: IntArray) -> Iterator[tuple[IntArray, IntArray]]:
    """Per frame with planar surfels: the positions in ``hits`` of the hits of the other frames,
    and that frame's planar surfels (skipping a frame where either is empty)."""
    for b in range(data.n_frames):
        in_b = np.flatnonzero((data.cell_frame == b) & surf.planar)
        sel = np.flatnonzero(data.frame[hits] != b)
        if len(in_b) and len(sel):
            yield sel, in_b


def grazing_rows(
    groups: Grazing, surf: Surfels, mapping: LineMapping, noise: SensorNoise, *, jacobian: bool = True
) -> tuple[FloatArray, FloatArray | None, FloatArray]:
    """The groups' residuals ``r`` ``(g,)`` (m), their derivatives w.r.t. the free parameters
    ``(g, k)`` (None unless ``jacobian``) and model variances ``(g,)`` (m², before the common
    scale), at ``mapping`` (see the module)."""
    t = groups.target
    n = mapping.rotate(surf.normal_obs[t], surf.line[t])
    d = mapping.apply(groups.xyz_obs, groups.line) - mapping.apply(surf.anchor_obs[t], surf.line[t])
    r = np.einsum("ni,ni->n", n, d)
    n_obs = np.einsum("nji,nj->ni", mapping.Rt[groups.line], n)
    var = (
        normal_variance(noise, groups.xyz_obs, n_obs) / groups.count
        + surf.var_m2[t] / surf.count[t]
        + (np.einsum("ni,ni->n", d, d) - r**2) * surf.normal_var_rad2[t]
    )
    if not jacobian:
        return np.asarray(r), None, np.asarray(var)
    J = mapping.normal_derivative(n, groups.xyz_obs, groups.line) - mapping.normal_derivative(
        n, surf.anchor_obs[t], surf.line[t]
    )
    return np.asarray(r), np.asarray(J), np.asarray(var)
