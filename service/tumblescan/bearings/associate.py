"""One frame, the recommended way: epipolar candidates, χ² gate, ML fixes, one-to-one assignment."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._typing import BoolArray, FloatArray, IntArray
from .assign import assign_sparse, close_alternatives
from .epipolar import Basis, candidate_pairs, epipolar_angles, rays_job
from .geometry import Fix, Observation, Station, closest_approach, take_rows, triangulate
from .inputs import Detections


@dataclass(frozen=True)
class FrameFixes:
    """The targets found in one frame: detection indices at each station and the ML fix."""

    i1: IntArray  # (k,) index into station 1's detections
    i2: IntArray  # (k,)
    p_job_m: FloatArray  # (k, 3)
    cov_m2: FloatArray  # (k, 3, 3)
    chi2: FloatArray  # (k,)
    range_m: FloatArray  # (k, 2)
    parallax_rad: FloatArray  # (k,)
    ambiguous: BoolArray  # (k,)
    corrected: BoolArray  # (k,) changed by a multi-frame step
    n1: int
    n2: int

    def __len__(self) -> int:
        return int(self.i1.size)


def observations(dets: tuple[Detections, Detections], i1: IntArray, i2: IntArray) -> tuple[Observation, Observation]:
    """The measured angles of the candidate pairs (i1[k], i2[k])."""
    return tuple(  # type: ignore[return-value]
        Observation(d.az_rad[i], d.el_rad[i], d.sigma_az_rad[i], d.sigma_el_rad[i])
        for d, i in zip(dets, (i1, i2), strict=True)
    )


@dataclass(frozen=True)
class Candidates:
    """Gated candidate pairs of one frame with their ML fixes."""

    i1: IntArray
    i2: IntArray
    fix: Fix


def gated_candidates(
    stations: tuple[Station, Station], basis: Basis, dets: tuple[Detections, Detections], gate: float
) -> Candidates:
    """Every pair passing the epipolar screen, cheirality and the ML χ² gate, with its fix."""
    # 1. Epipolar angle of every ray, and the pairs whose angles agree within the gate.
    psi1, var1 = epipolar_angles(dets[0], stations[0], basis)
    psi2, var2 = epipolar_angles(dets[1], stations[1], basis)
    i1, i2, _ = candidate_pairs(psi1, var1, psi2, var2, gate)
    # 2. Cheirality: the rays must meet in front of both stations.
    u1, u2 = rays_job(dets[0], stations[0])[i1], rays_job(dets[1], stations[1])[i2]
    r1, r2, _ = closest_approach(stations[0].p_job_m, u1, stations[1].p_job_m, u2)
    ahead = (r1 > 0.0) & (r2 > 0.0)
    i1, i2 = i1[ahead], i2[ahead]
    # 3. ML triangulation of the survivors; the 1-dof χ² gate again on the full residual.
    fix = triangulate(stations, observations(dets, i1, i2))
    keep = fix.ok & (fix.chi2 <= gate)
    return Candidates(i1[keep], i2[keep], take_rows(fix, keep))


def associate_frame(
    stations: tuple[Station, Station],
    basis: Basis,
    dets: tuple[Detections, Detections],
    *,
    gate: float = 16.0,
    ambiguity_margin: float = 4.0,
) -> FrameFixes:
    """Targets of one frame: the likelihood-ratio assignment (cost χ² − gate, leave-out 0)."""
    cand = gated_candidates(stations, basis, dets, gate)
    return assign_frame(cand, len(dets[0]), len(dets[1]), gate=gate, ambiguity_margin=ambiguity_margin)


def assign_frame(
    cand: Candidates,
    n1: int,
    n2: int,
    *,
    gate: float,
    ambiguity_margin: float,
    bonus: FloatArray | None = None,
) -> FrameFixes:
    """One-to-one assignment of a frame's candidates on ``χ² − gate − bonus``.

    ``bonus`` (per candidate, ≥ 0) favours pairs that other frames support; single-frame
    choices without a close alternative get the same bonus, so only ambiguous pairings can
    change. A pair taken only because of it (not the single-frame choice) is marked
    ``corrected``."""
    cost = cand.fix.chi2 - gate
    chosen = assign_sparse(cand.i1, cand.i2, cost, n1, n2)
    corrected = np.zeros(cand.i1.size, dtype=bool)
    if bonus is not None and np.any(bonus > 0):
        # A pairing with no close alternative in this frame keeps the same advantage, so only
        # ambiguous ones can change.
        single = chosen
        clear = single & ~close_alternatives(cand.i1, cand.i2, cand.fix.chi2, single, n1, n2, ambiguity_margin, gate)
        chosen = assign_sparse(cand.i1, cand.i2, cost - np.maximum(bonus, np.where(clear, bonus.max(), 0.0)), n1, n2)
        corrected = chosen & ~single
    ambiguous = close_alternatives(cand.i1, cand.i2, cand.fix.chi2, chosen, n1, n2, ambiguity_margin, gate)
    fix = take_rows(cand.fix, chosen)
    return FrameFixes(
        i1=cand.i1[chosen],
        i2=cand.i2[chosen],
        p_job_m=fix.p_job_m,
        cov_m2=fix.cov_m2,
        chi2=fix.chi2,
        range_m=fix.range_m,
        parallax_rad=fix.parallax_rad,
        ambiguous=ambiguous[chosen],
        corrected=corrected[chosen],
        n1=n1,
        n2=n2,
    )
