"""Starting motions for the dense fit: the vote on rotation angles, the consensus over
triplets of registered pairs, and the re-timing and re-registration starts they give."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from ..._typing import FloatArray
from ...geometry.rotations import axis_from_angles, rotate
from ...target.motion import canonical_params, rotation_matrices
from ..errors import FramesUnusableError
from ..initializer import InitialGuess, InitializerError, center_from_transforms, motion_from_transforms
from .consensus import cone_consensus
from .registration import PairTransforms, consistent_pairs

# A start this close to a fit that failed (axes in deg, rates in deg/s) is not refined again.
SAME_BASIN_DEG = 3.0
SAME_BASIN_DEG_S = 1.0


def retimed(
    xyz: FloatArray, tau: FloatArray, frame: NDArray[np.int64], mid: FloatArray, pairs: PairTransforms, start: Start
) -> FloatArray:
    """Points moved to their frame's mean time, rotating at the mean angular velocity of the pairs
    just before and after each frame. Voted start: the inlier pairs only (their median for a
    frame with none), about their common fixed point. Otherwise: registered where the pair
    agrees with the hypothesis, predicted by it where not, about the hypothesis's centre."""
    ok = start.inliers
    R = pairs.R if start.voted else np.where(ok[:, None, None], pairs.R, predicted_pairs(start.guess.x, mid).R)
    rotvec = Rotation.from_matrix(R).as_rotvec() / np.diff(mid)[:, None]
    omega = np.empty((len(mid), 3))
    for f in range(len(mid)):
        near = [k for k in (f - 1, f) if 0 <= k < len(rotvec) and (ok[k] or not start.voted)]
        omega[f] = rotvec[near].mean(axis=0) if near else np.median(rotvec[ok], axis=0)
    center = center_from_transforms(pairs.R[ok], pairs.t[ok]) if start.voted else start.guess.x[6:9]
    w = omega[frame]
    rate = np.linalg.norm(w, axis=1)
    axis = w / np.maximum(rate, 1e-300)[:, None]
    return np.asarray(center + rotate(axis, rate * (mid[frame] - tau), xyz - center), dtype=float)


def predicted_pairs(x: FloatArray, mid: FloatArray) -> PairTransforms:
    """The transforms between consecutive frames' mean times that motion ``x`` predicts."""
    R = rotation_matrices(x, mid)
    Q = R[1:] @ np.swapaxes(R[:-1], 1, 2)
    center = x[6:9]
    n = len(Q)
    return PairTransforms(Q, center - Q @ center, np.zeros(n), np.zeros(n))


def registration_start(pairs: PairTransforms, start: Start, mid: FloatArray) -> PairTransforms:
    """ICP starts: the registered transform where the pair agrees with the hypothesis (or for
    every pair after a vote), the predicted one where it does not (a pair registered onto a
    turned copy gets another chance)."""
    if start.voted:
        return pairs
    predicted = predicted_pairs(start.guess.x, mid)
    keep = start.inliers
    return PairTransforms(
        np.where(keep[:, None, None], pairs.R, predicted.R),
        np.where(keep[:, None], pairs.t, predicted.t),
        pairs.fitness,
        pairs.rmse_m,
    )


@dataclass(frozen=True)
class Start:
    """A starting motion and its inlier pairs; ``voted``: chosen by the vote on rotation angles."""

    guess: InitialGuess
    inliers: NDArray[np.bool_]
    voted: bool = False


def vote(pairs: PairTransforms, mid: FloatArray) -> Start:
    """The cone on the pairs whose rotation angle is near the median (every pair of the cone
    has the same angle): the path measured on the paper's grid."""
    ok = consistent_pairs(pairs)
    k = np.flatnonzero(ok)
    if len(k) < 3:
        raise FramesUnusableError(
            f"only {len(k)} of {len(ok)} consecutive frame pairs could be registered consistently; the initial "
            "motion needs 3 (do the frames overlap, and is the target rotating less than ~90 degrees per frame?)",
            field="file",
        )
    try:
        guess = motion_from_transforms(pairs.R[k], pairs.t[k], mid[k], mid[k + 1], 0.0)
    except InitializerError as exc:
        raise FramesUnusableError(f"the initial motion could not be formed: {exc}", field="file") from None
    return Start(guess=guess, inliers=ok, voted=True)


def consensus_start(pairs: PairTransforms, mid: FloatArray, seed: int) -> Start:
    try:
        found = cone_consensus(pairs.R, pairs.t, mid[:-1], mid[1:], 0.0, seed=seed)
        return Start(guess=found.guess, inliers=found.inliers)
    except InitializerError as exc:
        raise FramesUnusableError(
            f"the initial motion could not be formed from the registered frame pairs: {exc} (do the frames "
            "overlap, and is the target rotating less than ~90 degrees per frame?)",
            field="file",
        ) from None


def same_basin(x_start: FloatArray, x_fit: FloatArray) -> bool:
    """Whether a start lies where a fit ended: spin and precession axes within
    ``SAME_BASIN_DEG`` and rates within ``SAME_BASIN_DEG_S`` (canonical 9-vectors, rates >= 0).
    Registration starts lie a few degrees from the motion they lead to; distinct minima of the
    dense fit lie tens of degrees apart."""
    a, b = canonical_params(np.asarray(x_start, dtype=float)), canonical_params(np.asarray(x_fit, dtype=float))
    cos_limit = np.cos(np.radians(SAME_BASIN_DEG))
    axes_close = all(
        float(axis_from_angles(a[i], a[i + 1]) @ axis_from_angles(b[i], b[i + 1])) > cos_limit for i in (0, 3)
    )
    rates_close = bool(np.all(np.abs(a[[2, 5]] - b[[2, 5]]) < np.radians(SAME_BASIN_DEG_S)))
    return axes_close and rates_close
