"""Swarm start for dense frames: used when the registered pairs' cone fits poorly.

The consensus of the registered pairs (:mod:`tumblescan.consensus`) fails when too few pairs
registered right: a symmetric target spinning fast enough for each frame to be smeared by
tens of degrees. The pairs still hold the answer in a few of their triplets; the dense cloud
tells which. Recipe:

1. Hypotheses: the cone of every triplet of registered pairs; keep the ``HYPOTHESES`` that
   the most pairs agree with.
2. Rank them by a dense alignment cost (below), which needs no registration.
3. Start a particle swarm (:func:`tumblescan.swarm.particle_swarm`, NAIWPSO) on the best
   hypotheses, and let it search the 9 parameters on the same cost.

The cost maps a random sample of every frame's points to the reference time with the motion
``x`` and counts how many of frame ``f + 1``'s points fall in a voxel that frame ``f``
occupies (a voxel version of the "crispness" of a registered cloud, Sheehan et al. 2012):

    c(x) = -(1 / |S|) sum_{h in S} (1 / n_q) sum_f sum_{q in f + 1} [v_h(q(x)) in V_h(f, x)]

over voxel sizes ``S`` (a coarse one widens the basin, a fine one sharpens it). Consecutive
frames only: a wrong rate misaligns them by one frame period's worth of rotation, which keeps
the basin around the true motion wide.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..._typing import FloatArray, IntArray
from ...target.motion import to_reference
from ..swarm import SwarmConfig, particle_swarm
from .consensus import cone_hypotheses

# Hypotheses (of the triplets' cones) ranked by the dense cost; the best seed the swarm.
HYPOTHESES = 120
SWARM = SwarmConfig(variant="naiwpso", particles=48, iterations=30)
# Voxel sizes of the cost as fractions of the target's extent.
VOXEL_FRACTIONS = (1 / 15, 1 / 40)
OCCUPIED_PER_FRAME = 1000
QUERIES_PER_FRAME = 200
# The swarm's box: rates up to this multiple of the hypotheses' largest, centre within this
# fraction of the extent from the best hypothesis's centre.
RATE_MARGIN = 1.5
CENTER_FRACTION = 0.25
# Voxel indices (relative to the cloud's centroid) take 12 bits per axis; a motion turns points
# about its centre, so they stay within a few extents (~100 voxels) of the centroid.
_BITS = 12
_OFFSET = 1 << (_BITS - 1)


class OverlapCost:
    """The dense alignment cost ``c(x)`` of the module docstring, for many motions at once."""

    def __init__(
        self,
        xyz_m: FloatArray,
        tau_s: FloatArray,
        frame: IntArray,
        n_frames: int,
        *,
        voxel_m: tuple[float, ...],
        rng: np.random.Generator,
        occupied: int = OCCUPIED_PER_FRAME,
        queries: int = QUERIES_PER_FRAME,
    ) -> None:
        """xyz_m: ``(n, 3)`` points; tau_s: ``(n,)`` offsets from the reference time, seconds;
        frame: ``(n,)`` frame index; voxel_m: the voxel sizes ``S``, metres."""
        occ, qry = [], []
        for f in range(n_frames):
            idx = np.flatnonzero(frame == f)
            occ.append(rng.choice(idx, min(occupied, len(idx)), replace=False))
            if f > 0:
                qry.append(rng.choice(idx, min(queries, len(idx)), replace=False))
        o, q = np.concatenate(occ), np.concatenate(qry)
        self.origin = xyz_m[o].mean(axis=0)
        self.occupied = (xyz_m[o], tau_s[o], frame[o])
        self.queries = (xyz_m[q], tau_s[q], frame[q] - 1)
        self.voxel_m = voxel_m
        self.n_frames = n_frames

    @classmethod
    def for_extent(
        cls, xyz_m: FloatArray, tau_s: FloatArray, frame: IntArray, n_frames: int, *, extent_m: float, seed: int
    ) -> OverlapCost:
        """The cost with the default voxel sizes (``VOXEL_FRACTIONS`` of the target's extent)."""
        return cls(
            xyz_m,
            tau_s,
            frame,
            n_frames,
            voxel_m=tuple(extent_m * f for f in VOXEL_FRACTIONS),
            rng=np.random.default_rng(seed),
        )

    def __call__(self, x: FloatArray) -> FloatArray:
        """Cost of each row of ``x`` ``(k, 9)``: ``(k,)``, between -1 (every query hits) and 0."""
        k = len(x)
        occ = to_reference(x, self.occupied[0], self.occupied[1])
        qry = to_reference(x, self.queries[0], self.queries[1])
        hits = np.zeros(k)
        for h in self.voxel_m:
            # One key per (motion, frame, voxel): a query hits when its key is among frame f's.
            taken = np.unique(self._keys(occ, self.occupied[2], h))
            wanted = self._keys(qry, self.queries[2], h)
            at = np.minimum(np.searchsorted(taken, wanted), len(taken) - 1)
            hits += np.mean(taken[at] == wanted, axis=1)
        return np.asarray(-hits / len(self.voxel_m))

    def _keys(self, xyz: FloatArray, frame: IntArray, h: float) -> IntArray:
        v = np.clip(np.floor((xyz - self.origin) / h).astype(np.int64) + _OFFSET, 0, 2 * _OFFSET - 1)
        motion = np.arange(len(xyz), dtype=np.int64)[:, None]
        cell = (v[..., 0] << (2 * _BITS)) | (v[..., 1] << _BITS) | v[..., 2]
        return np.asarray(((motion * self.n_frames + frame) << (3 * _BITS)) | cell)


@dataclass(frozen=True)
class SearchResult:
    """Best motion found, its dense cost, and the best hypothesis's cost before the swarm."""

    x: FloatArray
    cost: float
    hypothesis_cost: float


def swarm_start(
    Rs: FloatArray,
    ts: FloatArray,
    mid_s: FloatArray,
    cost: OverlapCost,
    extent_m: float,
    *,
    seed: int = 0,
) -> SearchResult:
    """A starting motion from the registered pairs and the dense cost (module docstring).

    Rs, ts: ``(P, 3, 3)``, ``(P, 3)``: registered transforms between consecutive frames' mean
    times ``mid_s`` ``(P + 1,)`` (offsets from the reference time, seconds). Raises
    ``ValueError`` when no triplet of pairs forms a cone.
    """
    # 1. Triplets' cones, the ones most pairs agree with first.
    hypotheses, misfit = cone_hypotheses(Rs, ts, mid_s[:-1], mid_s[1:], 0.0, seed=seed)
    if not len(hypotheses):
        raise ValueError("no triplet of registered frame pairs forms a cone")
    hypotheses = hypotheses[np.argsort(misfit, kind="stable")[:HYPOTHESES]]
    # 2. Rank them by the dense cost.
    ranked = cost(hypotheses)
    order = np.argsort(ranked, kind="stable")
    best = hypotheses[order[0]]
    # 3. Swarm from the best hypotheses, in a box around them.
    lo = np.array([-np.pi, 0.0, 0.0, -np.pi, 0.0, 0.0, *(best[6:9] - CENTER_FRACTION * extent_m)])
    hi = np.array(
        [
            np.pi,
            np.pi,
            RATE_MARGIN * max(float(hypotheses[:, 2].max()), 1e-3),
            np.pi,
            np.pi,
            RATE_MARGIN * max(float(hypotheses[:, 5].max()), 1e-3),
            *(best[6:9] + CENTER_FRACTION * extent_m),
        ]
    )
    start = np.clip(hypotheses[order[: SWARM.particles // 2]], lo, hi)
    x, found, _ = particle_swarm(cost, lo, hi, SWARM, np.random.default_rng(seed), start=start)
    return SearchResult(x=x, cost=found, hypothesis_cost=float(ranked[order[0]]))
