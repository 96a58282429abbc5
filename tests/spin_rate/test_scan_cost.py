"""The scan's cost (``rigid.scan_cost``): zero at the true motion of noiseless tracks, and equal to a
direct per-track evaluation (each track's 4x4 plane scatter, its line from the two smallest
eigenvectors, re-projected through K at every observation's time)."""

from __future__ import annotations

import numpy as np
import pytest

from tumblescan.spin_rate.rigid import Observations, scan_cost
from tumblescan.spin_rate.rotation import rot, unit_from_angles

from .test_robust_fit import RANGE_M, synthetic_tracks

RADIUS = 3.0 / RANGE_M


def _direct_cost(obs: Observations, w: float, a: np.ndarray, c0: np.ndarray, clip_px: float) -> float:
    dt = obs.t_s - obs.t_s.min()
    total = 0.0
    for j in range(obs.n_tracks):
        sel = np.flatnonzero(obs.track == j)
        planes = []
        for i in sel:
            m = rot(a, -w * dt[i])[0] @ obs.normals[i]
            planes.append(np.r_[m * RADIUS, obs.normals[i] @ c0])
        P = np.array(planes)
        V = np.linalg.eigh(P.T @ P)[1]
        for i in sel:
            R = rot(a, w * dt[i])[0]
            X1, X2 = (R @ (V[:3, k] * RADIUS) + V[3, k] * c0 for k in (0, 1))
            line = np.cross(obs.K @ X1, obs.K @ X2)
            for e in obs.ends_px[i]:
                d = (line @ np.r_[e, 1.0]) / np.hypot(line[0], line[1])
                total += min(d * d, clip_px**2)
    return total


@pytest.mark.parametrize("seed", [3, 4])
def test_scan_cost_is_the_direct_per_track_cost(seed: int) -> None:
    axis = unit_from_angles(np.radians(50.0), np.radians(20.0))
    obs, truth = synthetic_tracks(seed, axis, 12.0, noise_px=0.1)
    rng = np.random.default_rng(seed)
    axes = np.array([unit_from_angles(rng.uniform(0, np.pi), rng.uniform(0, 2 * np.pi)) for _ in range(3)])
    omegas = np.array([0.9, 1.0, 1.3]) * float(truth["rate"])  # type: ignore[arg-type]
    c0 = np.asarray(truth["c0"]) + np.array([0.01, -0.02, 0.0])
    C = scan_cost(obs, omegas, np.vstack([axes, axis]), c0, float(obs.t_s.min()), RADIUS, clip_px=4.0)
    for k, w in enumerate(omegas):
        for i, a in enumerate([*axes, axis]):
            assert C[k, i] == pytest.approx(_direct_cost(obs, w, a, c0, 4.0), rel=1e-9, abs=1e-9)


def test_scan_cost_vanishes_at_the_true_motion_only() -> None:
    axis = unit_from_angles(np.radians(40.0), np.radians(-30.0))
    obs, truth = synthetic_tracks(5, axis, 10.0, noise_px=0.0)
    w = float(truth["rate"])  # type: ignore[arg-type]
    C = scan_cost(obs, np.array([w, 1.1 * w]), axis[None], np.asarray(truth["c0"]), 0.0, RADIUS, clip_px=5.0)
    assert C[0, 0] / len(obs.track) < 1e-8
    assert C[1, 0] / len(obs.track) > 0.1
