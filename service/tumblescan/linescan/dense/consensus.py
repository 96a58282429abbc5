"""Which registered frame pairs one cone motion explains: RANSAC over triplets of pairs.

A global registration of a symmetric or fast-turning target often returns the true rotation
composed with a symmetry of the target (a box with two equal panels is symmetric under
180 degree turns), or something unrelated when the frames are heavily smeared. Such pairs can
be the majority, so a vote on the rotation angle alone picks the wrong ones. Instead:

1. for triplets of pairs (all of them, or ``samples`` drawn at random), form the closed-form
   cone (:func:`tumblescan.initializer.cone_from_transforms`) and its spin-only twin;
2. score each hypothesis ``x`` by the truncated misfit over *every* pair,

       s(x) = sum_k min(|log(Q_k(x)^T R_k)|, e_max)^2,   Q_k(x) = R(t_to,k) R(t_from,k)^T,

   and keep the best: its inliers are the pairs with a misfit below ``e_max``;
3. polish on the inliers (:func:`tumblescan.initializer.motion_from_transforms`) and keep the
   polish only if it scores better.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from ..._typing import FloatArray
from ...geometry.rotations import axis_from_angles, rotation_matrix
from ...target.motion import N_PARAMS, canonical_params
from ..initializer import InitialGuess, InitializerError, cone_from_transforms, motion_from_transforms

# A registered pair agrees with a hypothesis when the rotations differ by less than this:
# registrations of smeared (not yet re-timed) frames are off by up to ~10 degrees.
INLIER_RAD = np.radians(15.0)
# Triplets tried at most; beyond this many, a seeded random sample.
SAMPLES = 600


@dataclass(frozen=True)
class Consensus:
    """The best cone hypothesis and the pairs it explains."""

    guess: InitialGuess
    inliers: NDArray[np.bool_]


def pair_misfit(x: FloatArray, Rs: FloatArray, tau_from_s: FloatArray, tau_to_s: FloatArray) -> FloatArray:
    """``|log(Q_k(x)^T R_k)|`` for each pair: the angle between predicted and registered rotation."""
    return pair_misfits(np.asarray(x, dtype=float)[None, :], Rs, tau_from_s, tau_to_s)[0]


def pair_misfits(xs: FloatArray, Rs: FloatArray, tau_from_s: FloatArray, tau_to_s: FloatArray) -> FloatArray:
    """:func:`pair_misfit` of each hypothesis ``xs`` ``(h, 9)`` at once, ``(h, P)``: the
    consensus scores hundreds of them, and one at a time most of the cost was numpy's per-call
    overhead on 3 x 3 matrices. Each entry is computed as :func:`target.motion.rotation_matrices`
    computes it, elementwise, so the values are those of one hypothesis at a time."""

    def rotations(tau: FloatArray) -> FloatArray:
        l_s = axis_from_angles(xs[:, 0], xs[:, 1])[:, None, :]
        l_p = axis_from_angles(xs[:, 3], xs[:, 4])[:, None, :]
        return np.asarray(rotation_matrix(l_p, xs[:, 5:6] * tau) @ rotation_matrix(l_s, xs[:, 2:3] * tau))

    to, since = rotations(np.asarray(tau_to_s, dtype=float)), rotations(np.asarray(tau_from_s, dtype=float))
    Q = to @ np.swapaxes(since, -1, -2)
    E = (np.swapaxes(Q, -1, -2) @ Rs).reshape(-1, 3, 3)
    return np.asarray(np.linalg.norm(Rotation.from_matrix(E).as_rotvec(), axis=1).reshape(len(xs), len(Rs)))


def cone_consensus(
    Rs: FloatArray,
    ts: FloatArray,
    t_from_s: FloatArray,
    t_to_s: FloatArray,
    reference_time_s: float,
    *,
    seed: int = 0,
    inlier_rad: float = INLIER_RAD,
    samples: int = SAMPLES,
) -> Consensus:
    """The cone motion most registered pairs agree with (see the module docstring).

    Rs: ``(P, 3, 3)``; ts: ``(P, 3)`` metres, with ``p(t_to) = R_k p(t_from) + t_k``; t_from_s,
    t_to_s: ``(P,)`` seconds. Raises :class:`InitializerError` when fewer than 3 pairs agree.
    """
    tau_from = np.asarray(t_from_s, dtype=float) - reference_time_s
    tau_to = np.asarray(t_to_s, dtype=float) - reference_time_s
    # 1-2. Hypotheses from triplets, scored on every pair.
    hypotheses, scores = cone_hypotheses(
        Rs, ts, t_from_s, t_to_s, reference_time_s, seed=seed, inlier_rad=inlier_rad, samples=samples
    )
    if not len(hypotheses):
        raise InitializerError(f"no 3 of the {len(Rs)} frame pairs form a cone")
    i = int(np.argmin(scores))
    best = InitialGuess(x=hypotheses[i], x_spin_only=without_precession(hypotheses[i]), cone_collapsed=False, passes=1)
    inliers = pair_misfit(best.x, Rs, tau_from, tau_to) < inlier_rad
    if inliers.sum() < 3:
        raise InitializerError(f"only {int(inliers.sum())} of {len(Rs)} frame pairs agree on one motion; 3 are needed")
    # 3. Polish on the inliers; keep the polish only if the pairs agree with it better.
    k = np.flatnonzero(inliers)
    polished = motion_from_transforms(Rs[k], ts[k], t_from_s[k], t_to_s[k], reference_time_s)
    polished_misfit = pair_misfit(polished.x, Rs, tau_from, tau_to)
    if _truncated_score(polished_misfit, inlier_rad) <= scores[i]:
        return Consensus(guess=polished, inliers=polished_misfit < inlier_rad)
    return Consensus(guess=best, inliers=inliers)


def _triplets(n: int, samples: int, seed: int) -> list[NDArray[np.int64]]:
    """Every triplet of ``range(n)`` in order, or ``samples`` distinct ones drawn at random."""
    every = itertools.combinations(range(n), 3)
    if n * (n - 1) * (n - 2) // 6 <= samples:
        return [np.array(t) for t in every]
    rng = np.random.default_rng(seed)
    drawn = {tuple(sorted(rng.choice(n, 3, replace=False).tolist())) for _ in range(samples)}
    return [np.array(t) for t in sorted(drawn)]


def cone_hypotheses(
    Rs: FloatArray,
    ts: FloatArray,
    t_from_s: FloatArray,
    t_to_s: FloatArray,
    reference_time_s: float,
    *,
    seed: int = 0,
    inlier_rad: float = INLIER_RAD,
    samples: int = SAMPLES,
) -> tuple[FloatArray, FloatArray]:
    """Every triplet's cone and spin-only start, canonical, ``(h, 9)``, and each one's truncated
    misfit ``s(x)`` over all pairs (radians squared); arguments as :func:`cone_consensus`."""
    tau_from = np.asarray(t_from_s, dtype=float) - reference_time_s
    tau_to = np.asarray(t_to_s, dtype=float) - reference_time_s
    found = []
    for k in _triplets(len(Rs), samples, seed):
        try:
            cone = cone_from_transforms(Rs[k], ts[k], t_from_s[k], t_to_s[k], reference_time_s)
        except InitializerError:
            continue
        found += [canonical_params(cone.x), canonical_params(cone.x_spin_only)]
    if not found:
        return np.empty((0, N_PARAMS)), np.empty(0)
    hypotheses = np.array(found)
    misfit = pair_misfits(hypotheses, Rs, tau_from, tau_to)
    return hypotheses, _truncated_score(misfit, inlier_rad)


def _truncated_score(misfit_rad: FloatArray, inlier_rad: float) -> FloatArray:
    """``s(x)`` of the module docstring from the pairs' misfits (last axis), radians squared."""
    return np.asarray(np.sum(np.minimum(misfit_rad, inlier_rad) ** 2, axis=-1))


def without_precession(x: FloatArray) -> FloatArray:
    """The spin-only start matching hypothesis ``x``: same spin and centre, no precession."""
    out = x.copy()
    out[3:6] = 0.0
    return out
