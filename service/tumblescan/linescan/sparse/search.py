"""The swarm search over feature tracks: the paper's pairwise cost (eq. 10) over the six
rotational parameters, the centre solved in closed form for each particle (see
``linescan/swarm.py`` for the swarm itself)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..._typing import FloatArray
from ...geometry.rotations import axis_from_angles, rotation_matrix
from ...target.motion import N_PARAMS
from ..swarm import SwarmConfig, particle_swarm, search_bounds
from ..tracks import Tracks
from .objective import consecutive_pairs


@dataclass(frozen=True)
class SwarmResult:
    """Best 9-vector found, its pairwise cost (m^2) and the best cost after each iteration."""

    x: FloatArray
    cost: float
    history: FloatArray


class PairwiseFitness:
    """Vectorized pairwise cost of many rotational parameter sets with the best centre each."""

    def __init__(self, tracks: Tracks, reference_time_s: float) -> None:
        first, second = consecutive_pairs(tracks)
        tau = tracks.t_s - reference_time_s
        self.tau1, self.tau2 = tau[first], tau[second]
        self.y1, self.y2 = tracks.xyz_m[first], tracks.xyz_m[second]

    def __call__(self, rot: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Cost ``(k,)`` and best centre ``(k, 3)`` for rotational parameters ``(k, 6)``."""
        l_s = axis_from_angles(rot[:, 0], rot[:, 1])[:, None, :]
        l_p = axis_from_angles(rot[:, 3], rot[:, 4])[:, None, :]
        w_s, w_p = rot[:, [2]], rot[:, [5]]
        # Q = R(t2) R(t1)^T = Rp(t2) Rs(t2 - t1) Rp(t1)^T
        Q = (
            rotation_matrix(l_p, w_p * self.tau2)
            @ rotation_matrix(l_s, w_s * (self.tau2 - self.tau1))
            @ rotation_matrix(l_p, -w_p * self.tau1)
        )  # (k, n, 3, 3)
        k, n = Q.shape[:2]
        b = (self.y2 - (Q @ self.y1[:, :, None])[..., 0]).reshape(k, 3 * n, 1)
        A = (np.eye(3) - Q).reshape(k, 3 * n, 3)
        At = A.transpose(0, 2, 1)
        AtA = At @ A
        # A tiny ridge keeps the all-parallel-axes case (pure spin) solvable.
        ridge = 1e-9 * np.trace(AtA, axis1=1, axis2=2)[:, None, None] * np.eye(3) + 1e-12 * np.eye(3)
        center = np.linalg.solve(AtA + ridge, At @ b)
        r = A @ center - b
        center = center[..., 0]
        return np.sum(r[..., 0] ** 2, axis=1), center


def swarm_search(
    tracks: Tracks,
    reference_time_s: float,
    config: SwarmConfig,
    rng: np.random.Generator,
    *,
    on_iteration: Callable[[int], None] | None = None,
) -> SwarmResult:
    """Run the configured swarm variant on the pairwise track cost; see the module docstring.
    ``on_iteration(i)`` is called after each iteration (it may raise to stop the search)."""
    fitness = PairwiseFitness(tracks, reference_time_s)
    lo, hi = search_bounds(config)
    best, best_cost, history = particle_swarm(
        lambda pos: fitness(pos)[0], lo, hi, config, rng, on_iteration=on_iteration
    )
    _, center = fitness(best[None, :])
    x = np.concatenate([best, center[0]])
    assert x.shape == (N_PARAMS,)
    return SwarmResult(x=x, cost=best_cost, history=history)
