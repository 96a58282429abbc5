"""Particle swarm search for the general case (method.md section 4), vectorized over particles.

Fitness is the paper's pairwise cost (eq. 10) over the six rotational parameters
``(a_s, b_s, w_s, a_p, b_p, w_p)``. The centre ``O_p`` enters linearly: with
``Q_i = R(t_{i+1}) R(t_i)^T`` each pair gives ``(I - Q_i) O_p = y_{i+1} - Q_i y_i``, so every
particle's best centre is one 3x3 solve (variable projection) and the swarm searches 6
dimensions instead of 9.

All variants move particles by

    v <- w v + c1 r1 (pbest - x) + c2 r2 (gbest - x),   x <- x + v

with ``r1, r2 ~ U(0, 1)`` per dimension, ``|v|`` capped at 20 % of each dimension's range,
azimuths wrapped and the other dimensions reflected at the bounds. They differ in ``w``,
``c1`` and ``c2`` (``s = iteration / (iterations - 1)``):

- ``pso``: inertia PSO, Shi & Eberhart (1998): ``w = 0.9 - 0.5 s``, ``c1 = c2 = 2``.
- ``tvac``: time-varying acceleration coefficients, Ratnaweera, Halgamuge & Watson (2004):
  ``w = 0.9 - 0.5 s``, ``c1 = 2.5 - 2 s``, ``c2 = 0.5 + 2 s``.
- ``apso``: adaptive PSO, Zhan, Zhang, Li & Chung (2009): evolutionary factor
  ``f = (d_g - d_min) / (d_max - d_min)`` from each particle's mean normalized distance to the
  others, ``w = 1 / (1 + 1.5 exp(-2.6 f))``; the state from ``f`` (crisp thresholds 0.25, 0.5,
  0.75 in place of the paper's fuzzy sets: convergence, exploitation, exploration, jumping
  out) moves ``c1, c2`` by ``delta ~ U(0.05, 0.1)`` (``+0.5d,+0.5d``; ``+0.5d,-0.5d``;
  ``+d,-d``; ``-d,+d``), clamped to ``[1.5, 2.5]`` and rescaled to sum at most 4. The
  elitist learning step is not implemented.
- ``naiwpso``: adaptive inertia from the success rate, Nickabadi, Ebadzadeh & Safabakhsh
  (2011) ``w = (w_max - w_min) S + w_min`` with ``w_max = 1, w_min = 0``, where, as
  method.md prescribes for NAIWPSO (Li Xuejun et al. 2016), a particle succeeds when its new
  fitness beats the previous global best; ``c1 = c2 = 1.49445``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from .._typing import FloatArray

Variant = Literal["pso", "tvac", "apso", "naiwpso"]
VARIANTS: tuple[Variant, ...] = ("pso", "tvac", "apso", "naiwpso")
# Azimuths of the two axes wrap around; every other dimension reflects at its bounds.
PERIODIC = (0, 3)


class SwarmConfig(BaseModel):
    """Swarm size, length, variant and the rate bounds it searches (degrees per second)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    variant: Variant = "naiwpso"
    particles: int = Field(100, ge=4, le=10_000)
    iterations: int = Field(35, ge=1, le=10_000)
    spin_rate_deg_s: tuple[float, float] = (0.0, 60.0)
    precession_rate_deg_s: tuple[float, float] = (0.0, 30.0)


def particle_swarm(
    cost_of: Callable[[FloatArray], FloatArray],
    lo: FloatArray,
    hi: FloatArray,
    config: SwarmConfig,
    rng: np.random.Generator,
    *,
    start: FloatArray | None = None,
    on_iteration: Callable[[int], None] | None = None,
) -> tuple[FloatArray, float, FloatArray]:
    """Minimize ``cost_of(positions (k, d)) -> (k,)`` within ``[lo, hi]``: best position, its cost,
    and the best cost after each iteration. Dimensions 0 and 3 are azimuths (periodic), 1 and 4
    polar angles; the first ``len(start)`` particles start at the rows of ``start``, the others
    with axes uniform on the sphere and every other dimension uniform in its bounds."""
    span = hi - lo
    k, dims = config.particles, len(lo)
    pos = lo + rng.random((k, dims)) * span
    pos[:, [1, 4]] = np.arccos(rng.uniform(-1, 1, (k, 2)))
    if start is not None:
        pos[: len(start)] = start[:k]
    vel = (rng.random((k, dims)) - 0.5) * 0.2 * span
    cost = cost_of(pos)
    pbest, pbest_cost = pos.copy(), cost.copy()
    g = int(np.argmin(cost))
    c1, c2 = (1.49445, 1.49445) if config.variant == "naiwpso" else (2.0, 2.0)
    w = 0.9
    history = np.empty(config.iterations)
    for it in range(config.iterations):
        s = it / max(config.iterations - 1, 1)
        # Coefficients for this step, per variant.
        if config.variant in ("pso", "tvac"):
            w = 0.9 - 0.5 * s
            if config.variant == "tvac":
                c1, c2 = 2.5 - 2.0 * s, 0.5 + 2.0 * s
        elif config.variant == "apso":
            w, c1, c2 = _apso_coefficients(pos, g, span, c1, c2, rng)
        # Move.
        r1, r2 = rng.random((2, k, dims))
        vel = w * vel + c1 * r1 * (pbest - pos) + c2 * r2 * (pbest[g] - pos)
        vel = np.clip(vel, -0.2 * span, 0.2 * span)
        pos, vel = _keep_insearch_bounds(pos + vel, vel, lo, hi)
        # Evaluate and update the memories.
        cost = cost_of(pos)
        if config.variant == "naiwpso":
            w = float(np.mean(cost < pbest_cost[g]))
        better = cost < pbest_cost
        pbest[better], pbest_cost[better] = pos[better], cost[better]
        g = int(np.argmin(pbest_cost))
        history[it] = pbest_cost[g]
        if on_iteration is not None:
            on_iteration(it)
    return pbest[g], float(pbest_cost[g]), history


def search_bounds(config: SwarmConfig) -> tuple[FloatArray, FloatArray]:
    ws = np.radians(config.spin_rate_deg_s)
    wp = np.radians(config.precession_rate_deg_s)
    lo = np.array([-np.pi, 0.0, ws[0], -np.pi, 0.0, wp[0]])
    hi = np.array([np.pi, np.pi, ws[1], np.pi, np.pi, wp[1]])
    return lo, hi


def _keep_insearch_bounds(
    pos: FloatArray, vel: FloatArray, lo: FloatArray, hi: FloatArray
) -> tuple[FloatArray, FloatArray]:
    span = hi - lo
    for d in PERIODIC:
        pos[:, d] = lo[d] + np.mod(pos[:, d] - lo[d], span[d])
    for d in (d for d in range(len(lo)) if d not in PERIODIC):  # the others reflect
        below, above = pos[:, d] < lo[d], pos[:, d] > hi[d]
        pos[below, d] = 2 * lo[d] - pos[below, d]
        pos[above, d] = 2 * hi[d] - pos[above, d]
        pos[:, d] = np.clip(pos[:, d], lo[d], hi[d])
        vel[below | above, d] *= -1
    return pos, vel


def _apso_coefficients(
    pos: FloatArray, g: int, span: FloatArray, c1: float, c2: float, rng: np.random.Generator
) -> tuple[float, float, float]:
    z = pos / span
    d = np.linalg.norm(z[:, None, :] - z[None, :, :], axis=-1).sum(axis=1) / (len(z) - 1)
    f = float((d[g] - d.min()) / max(d.max() - d.min(), 1e-12))
    w = 1.0 / (1.0 + 1.5 * np.exp(-2.6 * f))
    delta = rng.uniform(0.05, 0.1)
    if f < 0.25:  # convergence
        c1, c2 = c1 + 0.5 * delta, c2 + 0.5 * delta
    elif f < 0.5:  # exploitation
        c1, c2 = c1 + 0.5 * delta, c2 - 0.5 * delta
    elif f < 0.75:  # exploration
        c1, c2 = c1 + delta, c2 - delta
    else:  # jumping out
        c1, c2 = c1 - delta, c2 + delta
    c1, c2 = float(np.clip(c1, 1.5, 2.5)), float(np.clip(c2, 1.5, 2.5))
    if c1 + c2 > 4.0:
        c1, c2 = 4.0 * c1 / (c1 + c2), 4.0 * c2 / (c1 + c2)
    return w, c1, c2
