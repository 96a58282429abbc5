"""The rigid fit's failure modes on seeded synthetic line tracks (exact truth, no rendering):
a track that switches to another edge, a start far from the rate, the axis in the image plane,
and σ against the scatter of the estimates."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from tumblescan.spin_rate.association import reject_outliers
from tumblescan.spin_rate.rigid import Observations, fit_rigid
from tumblescan.spin_rate.rotation import rot, unit_from_angles
from tumblescan.spin_rate.search import best_of_starts, centre_distance, with_drift_if_needed
from tumblescan.spin_rate.starts import scan_starts
from tumblescan.spin_rate.tracking import reject_jumps

F_PX = 1100.0
K = np.array([[F_PX, 0.0, 256.0], [0.0, F_PX, 256.0], [0.0, 0.0, 1.0]])
RANGE_M = 40.0


def _box_edges(half: np.ndarray, centre: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The 12 edges (end, end) of a box (m, body frame)."""
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half + centre
    return [
        (corners[i], corners[j])
        for i in range(8)
        for j in range(i + 1, 8)
        if np.sum(np.abs(corners[i] - corners[j]) > 1e-9) == 1
    ]


def synthetic_tracks(
    seed: int, axis: np.ndarray, rate_deg_s: float, noise_px: float = 0.08, frames: int = 12, step_deg: float = 18.0,
    drift_px_per_frame: float = 0.0, R0: np.ndarray | None = None,
) -> tuple[Observations, dict[str, object]]:  # fmt: skip
    """Line observations of a box bus with a wing spinning about ``axis`` (camera frame): every
    edge whose middle faces the camera (its box's centre farther than the edge) in each frame,
    end points with ``noise_px`` of perpendicular noise; the centre drifts across the image by
    ``drift_px_per_frame``; ``R0`` (3, 3): the body's attitude at t = 0 (random when None).
    Returns the observations and the truth."""
    rng = np.random.default_rng(seed)
    edges = _box_edges(np.array([0.8, 0.7, 1.0]), np.zeros(3))
    edges += _box_edges(np.array([0.02, 2.0, 0.8]), np.array([0.0, 2.9, 0.0]))
    R_random = rot(unit_from_angles(rng.uniform(0, np.pi), rng.uniform(0, 2 * np.pi)), rng.uniform(0, 2 * np.pi))[0]
    R0 = R_random if R0 is None else R0
    c = np.array([rng.uniform(-2, 2), rng.uniform(-2, 2), RANGE_M])
    w = np.radians(rate_deg_s)
    t = np.cumsum(np.r_[0.0, np.radians(step_deg) / w * rng.uniform(0.97, 1.03, frames - 1)])
    v = np.array([0.6, 0.8, 0.0]) * drift_px_per_frame * RANGE_M / F_PX / (np.radians(step_deg) / w)
    trk, tt, ends = [], [], []
    for tk in t:
        R = rot(axis, w * tk)[0] @ R0
        ct = c + v * tk
        for j, (p, q) in enumerate(edges):
            P, Q = ct + R @ p, ct + R @ q
            if (P + Q)[2] / 2 > ct[2] + 0.3 or rng.uniform() < 0.3:  # far side, or missed
                continue
            uv = np.array([K @ P, K @ Q])
            uv = uv[:, :2] / uv[:, 2:]
            d = (uv[1] - uv[0]) / np.linalg.norm(uv[1] - uv[0])
            n = np.array([-d[1], d[0]])
            uv = uv + rng.normal(0, noise_px, (2, 1)) * n
            trk.append(j)
            tt.append(tk)
            ends.append(uv)
    trk_a = np.array(trk)
    _, track = np.unique(trk_a, return_inverse=True)
    keep = np.bincount(track)[track] >= 4
    _, track = np.unique(track[keep], return_inverse=True)
    obs = Observations.build(track, np.array(tt)[keep], np.array(ends)[keep], K)
    return obs, {"rate": w, "axis": axis, "c0": c / c[2], "t": t}


def test_a_track_that_switches_edges_is_cut_by_the_outlier_rejection() -> None:
    axis = unit_from_angles(np.radians(40.0), np.radians(20.0))
    obs, truth = synthetic_tracks(11, axis, 30.0)
    # The longest track follows another, nearly parallel edge for its second half: a line 1.5 px
    # away, turned by 0.5°, as when the right edge was missed and its neighbour taken instead.
    j = int(np.argmax(np.bincount(obs.track)))
    rows = np.flatnonzero(obs.track == j)
    ends = obs.ends_px.copy()
    for r in rows[len(rows) // 2 :]:
        e = ends[r]
        d = (e[1] - e[0]) / np.linalg.norm(e[1] - e[0])
        mid = e.mean(axis=0) + 1.5 * np.array([-d[1], d[0]])
        turned = rot(np.array([0.0, 0.0, 1.0]), np.radians(0.5))[0][:2, :2] @ (e - e.mean(axis=0)).T
        ends[r] = mid + turned.T
    bad = Observations.build(obs.track, obs.t_s, ends, K)
    t0 = float(truth["t"][0])  # type: ignore[index]
    fit = fit_rigid(bad, truth["rate"], axis, truth["c0"], t0)  # type: ignore[arg-type]
    kept, clean = reject_outliers(bad, fit, t0)
    err = abs(clean.omega_rad_s - truth["rate"]) / truth["rate"]  # type: ignore[operator]
    assert err < 0.002, (np.degrees(fit.omega_rad_s), np.degrees(clean.omega_rad_s))
    assert len(kept.track) < len(bad.track)  # the switched observations went
    assert abs(clean.omega_rad_s - truth["rate"]) <= 4 * clean.sigma_omega_rad_s + np.radians(0.002)  # type: ignore[operator]


def test_a_jump_far_off_the_pairs_prediction_is_cut() -> None:
    pairs = [(0, 0), (1, 1), (2, 2), (3, 3), (4, 4)]
    offsets = np.array([0.2, 0.3, 0.25, 2.6, 0.2])  # the fourth edge jumped 2.6 px to a neighbour
    assert reject_jumps(pairs, offsets) == [(0, 0), (1, 1), (2, 2), (4, 4)]
    assert reject_jumps(pairs, np.full(5, 0.3)) == pairs  # a pair turned uniformly: nothing cut


def test_the_plausibility_distances_do_not_depend_on_the_scale_the_fit_ended_at() -> None:
    # The images fix the scene up to a scale about the camera: with c0_z = 1, c0 slides along the
    # axis as the scene scales, and a fit of the true motion can end anywhere on that family. The
    # distances that rule a fit implausible must not: a fit of the truth once ended at 1.16 times
    # the scale, its axis 2.1 radii from the centre guess (over the limit of 2) instead of 0.4, and
    # the wrong twin won (CI, a start at twice the rate).
    axis = unit_from_angles(np.radians(55.0), np.radians(-70.0))
    obs, truth = synthetic_tracks(5, axis, 24.0)
    centre = np.asarray(truth["c0"])
    t0 = float(truth["t"][0])  # type: ignore[index]
    fit = fit_rigid(obs, float(truth["rate"]), axis, centre, t0)  # type: ignore[arg-type]
    a = fit.axis
    miss, to_lines = centre_distance(fit, centre)
    for scale in (0.8, 1.16, 1.5):
        slide = (1 - scale) / a[2]  # back to depth 1 along the axis
        moved = replace(fit, c0=scale * fit.c0 + slide * a, lines_p=scale * fit.lines_p - slide * a)
        assert moved.c0[2] == pytest.approx(1.0)
        miss_moved, to_lines_moved = centre_distance(moved, centre)
        assert miss_moved == pytest.approx(miss, rel=1e-9, abs=1e-12)
        np.testing.assert_allclose(to_lines_moved, to_lines, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("factor", [0.5, 2.0])
def test_a_start_at_half_or_double_the_rate_finds_the_rate(factor: float) -> None:
    axis = unit_from_angles(np.radians(55.0), np.radians(-70.0))
    obs, truth = synthetic_tracks(5, axis, 24.0)
    t0 = float(truth["t"][0])  # type: ignore[index]
    w = float(truth["rate"]) * factor  # type: ignore[arg-type]
    start = (w, unit_from_angles(np.radians(30.0), np.radians(-40.0)), np.asarray(truth["c0"]))
    fit = best_of_starts(obs, [start], t0, 0.2 * w, 5.0 * w, np.asarray(truth["c0"]), 0.08)
    assert abs(fit.omega_rad_s - truth["rate"]) / truth["rate"] < 0.003, np.degrees(fit.omega_rad_s)  # type: ignore[operator]


def test_an_axis_in_the_image_plane_is_found_by_the_scan() -> None:
    axis = np.array([np.cos(np.radians(35.0)), np.sin(np.radians(35.0)), 0.02])
    axis /= np.linalg.norm(axis)
    obs, truth = synthetic_tracks(8, axis, 18.0, step_deg=20.0)
    t = np.asarray(truth["t"])
    span = float(t[-1] - t[0])
    omegas = np.arange(np.radians(6.0), np.radians(40.0), np.radians(6.0) / span)
    c0 = np.asarray(truth["c0"])
    starts = scan_starts(obs, omegas, c0, 0.08, float(t[0]), [], 0, lambda *_: None)
    fit = best_of_starts(obs, starts, float(t[0]), omegas[0], omegas[-1], c0, 0.08)
    assert abs(fit.omega_rad_s - truth["rate"]) / truth["rate"] < 0.01, np.degrees(fit.omega_rad_s)  # type: ignore[operator]


def test_a_drifting_centre_is_fitted_with_a_velocity_and_a_still_one_without() -> None:
    axis = unit_from_angles(np.radians(35.0), np.radians(120.0))
    for drift_px, expect in ((1.2, True), (0.0, False)):
        obs, truth = synthetic_tracks(4, axis, 28.0, drift_px_per_frame=drift_px)
        t0 = float(truth["t"][0])  # type: ignore[index]
        still = fit_rigid(obs, truth["rate"], axis, truth["c0"], t0)  # type: ignore[arg-type]
        fit = with_drift_if_needed(obs, still, t0)
        assert fit.drift == expect
        assert abs(fit.omega_rad_s - truth["rate"]) / truth["rate"] < 0.002, np.degrees(fit.omega_rad_s)  # type: ignore[operator]
