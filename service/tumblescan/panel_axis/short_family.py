"""The wing's short edges (its ends and sub-panel gaps), found given the axis.

Every direction orthogonal to the axis ``d`` is ``s(ψ) = cos ψ·e1 + sin ψ·e2`` for an angle ψ about
it. An image line whose plane has unit normal ``n`` holds exactly one such direction,
``s = normalize(n × d)``, so each edge across the axis votes for one ψ (mod π), with
``σ_ψ = σ(n·s)/|n × d|`` (a rotation δψ moves ``n·s`` by ``n·(d × s)·δψ = |n × d|·δψ``). The wing's
short edges share one ψ; the bus's edges across the axis share others (the drive angle turns the
wing about the axis). Grouping by ψ is a one-dimensional search, which keeps a wing's two distant
tips together where a RANSAC over plane pairs can pair a tip with a nearer bus edge.

Which ψ is the wing's: the bus sits between the wings, so the wing's short edges lie in the outer
parts of the axis's image span (beyond ``INNER_FRACTION`` of it on each side of the middle). The
cluster with the most outer edge length wins; it needs 2 edges.
"""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray
from ..geometry.rotations import tangent_basis
from .edges import Edge, Family

INNER_FRACTION = 0.15  # half-width of the middle of the span (the bus) as a fraction of the span
CROSS_MIN_DEG = 20.0  # image angle to the axis over which an edge may be a short edge
PSI_SLACK_DEG = 0.3  # added to the 3σ gate (edge-model bias)
MIN_CROSS_NORM = 0.05  # |n × d| under it: the edge's plane holds the axis (an edge along it)


def short_family(edges: list[Edge], axis_family: Family, d: FloatArray) -> Family | None:
    """The wing's short edges (see the module docstring) among ``edges`` not in ``axis_family``,
    for the unit axis ``d`` (3,) camera frame; None when fewer than 2 agree."""
    a = axis_family.image_direction()
    ends = np.array([a @ p for e in axis_family.edges for p in e.line.endpoints_px])
    lo, hi = float(ends.min()), float(ends.max())
    if hi - lo < 1.0:
        return None
    members = {id(e) for e in axis_family.edges}
    cand = [
        e
        for e in edges
        if id(e) not in members and np.arccos(min(1.0, abs(float(e.line.direction @ a)))) > np.radians(CROSS_MIN_DEG)
    ]
    if len(cand) < 2:
        return None
    e1, e2 = tangent_basis(d)
    psi, sig, keep = [], [], []
    for e in cand:
        c = np.cross(e.plane.normal, d)
        nc = float(np.linalg.norm(c))
        if nc < MIN_CROSS_NORM:
            continue
        s = c / nc
        psi.append(float(np.arctan2(s @ e2, s @ e1)) % np.pi)
        sig.append(float(np.sqrt(e.plane.sigma2(s))) / nc)
        keep.append(e)
    if len(keep) < 2:
        return None
    psi_a, sig_a = np.array(psi), np.array(sig)
    pos = np.array([(a @ e.line.centroid_px - lo) / (hi - lo) for e in keep])
    outer = np.abs(pos - 0.5) > INNER_FRACTION
    length = np.array([e.length_px for e in keep])
    slack = np.radians(PSI_SLACK_DEG)

    def near(center: float, s_center: float) -> np.ndarray:
        dpsi = np.abs((psi_a - center + np.pi / 2) % np.pi - np.pi / 2)
        return np.asarray(outer & (dpsi <= 3 * np.hypot(sig_a, s_center) + slack))

    best, best_score = None, 0.0
    for k in np.flatnonzero(outer):
        m = near(psi_a[k], sig_a[k])
        score = float(length[m].sum())
        if np.count_nonzero(m) >= 2 and score > best_score:
            best, best_score = m, score
    if best is None:
        return None
    # Refine: the members' weighted mean ψ, then the edges agreeing with it.
    w = 1.0 / np.maximum(sig_a[best], 1e-9) ** 2
    ref = psi_a[np.flatnonzero(best)[np.argmax(w)]]
    dpsi = (psi_a[best] - ref + np.pi / 2) % np.pi - np.pi / 2
    center = float(ref + (w * dpsi).sum() / w.sum())
    final = near(center, float(np.sqrt(1.0 / w.sum())))
    if np.count_nonzero(final) < 2:
        final = best
    chosen = [e for e, f in zip(keep, final, strict=True) if f]
    direction = np.cos(center) * e1 + np.sin(center) * e2
    return Family(chosen, direction)
