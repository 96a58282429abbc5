"""The starts for an axis near the image plane (the image does not turn): a ladder of rates over
the whole prior range, each with an image-plane axis, and the multi-start's near-plane finalists."""

from __future__ import annotations

import numpy as np

from tumblescan.spin_rate.rotation import los_angle_deg, rot, unit_from_angles
from tumblescan.spin_rate.search import best_of_starts
from tumblescan.spin_rate.starts import PLANE_LADDER_RATIO, PLANE_TILTS_DEG, plane_ladder_starts

from .test_robust_fit import synthetic_tracks


def _flat_spin_tracks(seed: int, axis: np.ndarray, rate_deg_s: float):  # type: ignore[no-untyped-def]
    """Tracks of the synthetic box and wing spinning about its long body axis (z) set along
    ``axis``, as the simulator's flat spin about the major axis: a third of the edges lie along the
    axis and two thirds across it (the lines that barely move off their image lines)."""
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(z, axis)
    R_align = rot(v / np.linalg.norm(v), np.arctan2(np.linalg.norm(v), z @ axis))[0]
    R0 = rot(axis, 1.3)[0] @ R_align
    return synthetic_tracks(seed, axis, rate_deg_s, noise_px=0.3, frames=10, step_deg=15.0, R0=R0)


def test_the_ladder_spans_the_rate_range_with_image_plane_axes() -> None:
    axis = unit_from_angles(np.radians(87.0), np.radians(35.0))
    obs, truth = _flat_spin_tracks(52, axis, 20.0)
    c0 = np.asarray(truth["c0"])
    w_lo, w_hi = np.radians(0.5), np.radians(60.0)
    starts = plane_ladder_starts(obs, w_lo, w_hi, c0, 0.08, float(np.asarray(truth["t"])[0]))
    rates = np.array([s[0] for s in starts])
    assert np.isclose(rates[0], w_lo) and rates[-1] <= w_hi < rates[-1] * PLANE_LADDER_RATIO
    assert np.allclose(rates[1:] / rates[:-1], PLANE_LADDER_RATIO)
    assert all(los_angle_deg(a) >= 90.0 - max(PLANE_TILTS_DEG) - 1e-9 for _, a, _ in starts)
    assert all(np.array_equal(c, c0) for _, _, c in starts)


def test_slow_starts_tilted_toward_the_line_of_sight_do_not_hide_the_image_plane_axis() -> None:
    # Only a slow start with its axis 25° from the line of sight, as the scan gives on the rendered
    # sequences where lines across the axis dominate; with the ladder a near-plane finalist is
    # carried to convergence and wins.
    axis = unit_from_angles(np.radians(87.0), np.radians(35.0))
    obs, truth = _flat_spin_tracks(52, axis, 20.0)
    c0 = np.asarray(truth["c0"])
    t0 = float(np.asarray(truth["t"])[0])
    w_lo, w_hi = np.radians(0.5), np.radians(60.0)
    slow = [(np.radians(2.0), unit_from_angles(np.radians(25.0), np.radians(120.0)), c0)]
    ladder = plane_ladder_starts(obs, w_lo, w_hi, c0, 0.08, t0)
    fit = best_of_starts(obs, slow, t0, w_lo, w_hi, c0, 0.08, ladder)
    rate = float(truth["rate"])
    assert abs(fit.omega_rad_s - rate) / rate < 0.01, np.degrees(fit.omega_rad_s)
    assert los_angle_deg(fit.axis) > 80.0


def test_one_minimum_reached_by_several_finalists_is_kept_once() -> None:
    # Near the image plane two or three finalists often converge to one minimum; it is restarted
    # and polished once. Fits apart by more than the rounding of one minimum are all kept.
    from dataclasses import replace

    from tumblescan.spin_rate.rigid import fit_rigid
    from tumblescan.spin_rate.search import _distinct_minima

    axis = unit_from_angles(np.radians(87.0), np.radians(30.0))
    obs, truth = _flat_spin_tracks(5, axis, 20.0)
    fit = fit_rigid(obs, float(truth["rate"]), axis, np.asarray(truth["c0"]), float(np.asarray(truth["t"])[0]))
    w = fit.omega_rad_s
    copy = replace(fit, omega_rad_s=w * (1 + 1e-7), cost=fit.cost * (1 + 1e-7))
    kept = _distinct_minima([fit, copy])
    assert len(kept) == 1 and kept[0] is fit
    other_rate = replace(fit, omega_rad_s=w * 1.001)
    a = fit.axis + np.array([0.0, 0.0, 0.003])
    other_axis = replace(fit, axis=a / np.linalg.norm(a))
    assert len(_distinct_minima([fit, copy, other_rate, other_axis])) == 3
