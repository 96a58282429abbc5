"""Rival rates: fits at another rate that explain the data about as well as the winner.

With the axis near the image plane the rate is held by short arcs of the edges along the axis, and
the search can end in a slow basin (benchmark: 6 of 38 runs 72-98 % off with a σ of 0.1-0.3 deg/s)
while the truth lies in a narrow basin elsewhere. One fit's σ, a curvature at its own minimum, cannot
say so; comparing the winner with fits at other rates on the same tracks can: a cheaper one wins, one
about as good is a rival that σ covers (``sigma_with_rivals``).
"""

from __future__ import annotations

from functools import partial

import numpy as np

from .._typing import FloatArray
from ..numerics.parallel import parallel_map
from .rigid import Observations, RigidFit, fit_rigid
from .search import axis_polished, common_costs, restarted, same_basin
from .starts import Start, plane_axis_starts

# A fit at a rate over RATE_RIVAL_MIN_REL off the winner's whose cost is within this Δχ² (the
# twin's test) is a rival the data do not rule out (``rate_rivals``).
RATE_RIVAL_MIN_REL = 0.05
RATE_RIVAL_DELTA_CHI2 = 9.0


def peak_fits(
    obs: Observations, fit: RigidFit, peaks_rad_s: list[float], t_ref: float, radius: float
) -> list[RigidFit]:
    """Fits of ``obs`` started at each periodogram peak (rad/s) over ``RATE_RIVAL_MIN_REL`` from
    ``fit``'s rate, each from the image-plane axis the scan ranks best at that rate
    (``starts.plane_axis_starts``) and ``fit``'s centre, then restarted and axis-polished as the
    search's near-plane finalists.

    The mask's outline turns with the body whatever the tracks do, so its periodogram peaks near the
    true rate even where the search's starts all led to a slow basin (benchmark plane_109_clean: the
    winner 3.03 deg/s, a fit from the peak 29.36 deg/s at a Δχ² of -39 below it; truth 29.63).
    ``radius``: the target's radius in units of the range; ``t_ref``: reference time (s)."""
    far = [w for w in peaks_rad_s if abs(w - fit.omega_rad_s) > RATE_RIVAL_MIN_REL * fit.omega_rad_s]
    starts = plane_axis_starts(obs, np.asarray(far, dtype=float), fit.c0, radius, t_ref)
    return parallel_map(partial(_peak_fit, obs, drift=fit.drift, t_ref=t_ref), starts)


def _peak_fit(obs: Observations, start: Start, *, drift: bool, t_ref: float) -> RigidFit:
    """One fit of ``peak_fits``: converged from ``start`` (ω, axis, c0), restarted, axis-polished."""
    fit = fit_rigid(obs, *start, t_ref, drift=drift)
    return axis_polished(obs, restarted(obs, fit, t_ref), t_ref)


def rate_rivals(
    obs: Observations, fit: RigidFit, finalists: list[RigidFit], t_ref: float, centre: FloatArray, radius: float
) -> list[RigidFit]:
    """The fits of ``obs`` at a rate distinct from ``fit``'s that explain the data almost as well:
    each of ``finalists`` (the search's converged fits, of possibly other observations) whose rate
    differs from ``fit``'s by over ``RATE_RIVAL_MIN_REL`` is refitted to ``obs`` from its own rate,
    axis and centre, and is a rival when it stays that far off and its common-scale Cauchy cost is
    within ``Δχ² = 2·Δcost/σ² < RATE_RIVAL_DELTA_CHI2`` of ``fit``'s (σ = ``fit``'s rms, as for the
    weak-perspective twin) and it is plausible (``common_costs``). Farthest rate first.

    With the axis near the image plane the rate is held by short arcs of the edges along the axis,
    and a fit can end in a basin whose rate is far off while a rival basin fits nearly as well
    (benchmark: 6 of 38 runs at 72-98 % off with a σ of 0.1-0.3 deg/s); one fit's σ, a curvature
    at its own minimum, cannot say so."""
    s2 = max(fit.rms_px**2, 1e-6)
    rivals: list[RigidFit] = []
    for f in finalists:
        if abs(f.omega_rad_s - fit.omega_rad_s) <= RATE_RIVAL_MIN_REL * fit.omega_rad_s:
            continue
        if any(same_basin(f, r) for r in rivals):
            continue
        again = fit_rigid(obs, f.omega_rad_s, f.axis, f.c0, t_ref, drift=fit.drift)
        if abs(again.omega_rad_s - fit.omega_rad_s) <= RATE_RIVAL_MIN_REL * fit.omega_rad_s:
            continue
        cost = common_costs([fit, again], radius, centre)
        if np.isfinite(cost[1]) and 2.0 * (cost[1] - cost[0]) / s2 < RATE_RIVAL_DELTA_CHI2:
            rivals.append(again)
    return sorted(rivals, key=lambda r: -abs(r.omega_rad_s - fit.omega_rad_s))


def sigma_with_rivals(sigma: float, rate: float, rival_rates: list[float]) -> float:
    """σ (deg/s) of a ``rate`` whose rivals (``rival_rates``, deg/s) the data do not rule out: at
    least the spread of an equal mixture of the rate and its farthest rival, half their distance,
    so that |error| <= 4σ holds whichever of the two is true; ``sigma`` without rivals."""
    if not rival_rates:
        return sigma
    far = max(abs(r - rate) for r in rival_rates)
    return float(np.hypot(sigma, 0.5 * far))
