"""Rival rates near the image plane: found only when the data do not rule them out, and σ covers them."""

from __future__ import annotations

import numpy as np

from tumblescan.spin_rate.rigid import fit_rigid
from tumblescan.spin_rate.rivals import peak_fits, rate_rivals, sigma_with_rivals
from tumblescan.spin_rate.search import common_costs

from .test_track_split import _spliced_tracks


def test_a_worse_basin_is_no_rival_and_a_better_one_is() -> None:
    clean, _, truth = _spliced_tracks(3)
    t0 = float(np.asarray(truth["t"])[0])
    c0, axis, rate = np.asarray(truth["c0"]), np.asarray(truth["axis"]), float(truth["rate"])  # type: ignore[arg-type]
    fit = fit_rigid(clean, rate, axis, c0, t0)
    # A fit held 30 % slow (one step from a start there, a step the solver rejects: from 20 % slow
    # its Gauss-Newton step lands within 4 %): far off and far worse than the winner.
    slow = fit_rigid(clean, 0.7 * rate, axis, c0, t0, max_nfev=1, passes=0)
    assert abs(slow.omega_rad_s - rate) > 0.15 * rate
    assert rate_rivals(clean, fit, [fit, slow], t0, c0, 0.08) == []  # refitted, it is the winner's basin
    # Judged from the slow fit (a winner that collapsed), the true rate fits better: it is reported.
    rivals = rate_rivals(clean, slow, [slow, fit], t0, c0, 0.08)
    assert len(rivals) == 1 and abs(rivals[0].omega_rad_s - rate) < 0.005 * rate
    sigma = sigma_with_rivals(0.01, float(np.degrees(slow.omega_rad_s)), [float(np.degrees(rivals[0].omega_rad_s))])
    assert abs(np.degrees(slow.omega_rad_s - rate)) <= 4 * sigma + 0.002


def test_sigma_covers_the_farthest_rival() -> None:
    assert sigma_with_rivals(0.03, 23.0, []) == 0.03
    sigma = sigma_with_rivals(0.03, 23.0, [15.0, 30.0])
    assert sigma >= 0.5 * 8.0
    for truth in (15.0, 23.0, 30.0):
        assert abs(23.0 - truth) <= 4 * sigma + 0.002


def test_a_fit_from_the_periodogram_peak_leaves_a_slow_basin_and_not_the_right_one() -> None:
    clean, _, truth = _spliced_tracks(4)
    t0 = float(np.asarray(truth["t"])[0])
    c0, axis, rate = np.asarray(truth["c0"]), np.asarray(truth["axis"]), float(truth["rate"])  # type: ignore[arg-type]
    # A winner held 40 % slow (as a collapsed search ends): the fit from a peak 8 % off the truth,
    # with an image-plane axis of the scan's choosing, reaches the true rate and costs less.
    slow = fit_rigid(clean, 0.6 * rate, axis, c0, t0, max_nfev=1, passes=0)
    found = peak_fits(clean, slow, [1.08 * rate], t0, 0.08)
    assert len(found) == 1 and abs(found[0].omega_rad_s - rate) < 0.005 * rate
    assert float(np.degrees(np.arccos(abs(found[0].axis @ axis)))) < 1.0
    cost = common_costs([slow, found[0]])
    assert cost[1] < cost[0]
    # From the right winner: a peak within 5 % is its own basin (no fit); from peaks at a slow or a
    # double rate the cheapest fit is still at the true rate.
    fit = fit_rigid(clean, rate, axis, c0, t0)
    assert peak_fits(clean, fit, [1.03 * rate], t0, 0.08) == []
    others = peak_fits(clean, fit, [0.4 * rate, 2.0 * rate], t0, 0.08)
    best = [fit, *others][int(np.argmin(common_costs([fit, *others])))]
    assert abs(best.omega_rad_s - rate) < 0.005 * rate
