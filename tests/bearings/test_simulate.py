"""The simulator: truth consistent with the documents, the scenes' geometry as specified."""

from __future__ import annotations

import numpy as np
import pytest

from tumblescan.bearings.geometry import bearings_of
from tumblescan.bearings.inputs import parse_input
from tumblescan.bearings.scenes import SCENES
from tumblescan.bearings.simulate import SimulationConfig, simulate


@pytest.mark.parametrize("scene", SCENES)
def test_noise_free_bearings_point_at_the_true_targets(scene: str) -> None:
    sim = simulate(SimulationConfig(scene=scene, seed=3, targets=20 if scene == "swarm" else None, frames=3))
    clean = parse_input(sim.input_noise_free)
    noisy = parse_input(sim.input)
    for fr, fn, tf in zip(clean.frames, noisy.frames, sim.truth["frames"], strict=True):
        for s, st in enumerate(clean.stations):
            assert fr.detections[s].ids == fn.detections[s].ids  # same ids, same order
            seen = [(t["detections"][st.id], t["position_m"]) for t in tf["targets"] if t["detections"][st.id]]
            index = {d: n for n, d in enumerate(fr.detections[s].ids)}
            rows = np.array([index[d] for d, _ in seen])
            az, el = bearings_of(np.array([p for _, p in seen]), st)
            np.testing.assert_allclose(np.cos(fr.detections[s].az_rad[rows] - az), 1.0, atol=1e-15)
            np.testing.assert_allclose(fr.detections[s].el_rad[rows], el, atol=1e-12)
            # The noisy copy is off by about the declared σ, not more.
            d_el = fn.detections[s].el_rad[rows] - el
            assert np.all(np.abs(d_el) < 6 * fn.detections[s].sigma_el_rad[rows])


def test_every_detection_belongs_to_one_target_or_is_a_false_alarm() -> None:
    sim = simulate(SimulationConfig(scene="paper", seed=5, clutter=0.4, p_miss=0.2))
    n_true = n_all = 0
    for fr, tf in zip(sim.input["frames"], sim.truth["frames"], strict=True):
        ids = [d["id"] for dets in fr["detections"].values() for d in dets]
        true_ids = [v for t in tf["targets"] for v in t["detections"].values() if v is not None]
        assert len(set(true_ids)) == len(true_ids)
        assert set(true_ids) <= set(ids)
        for t in tf["targets"]:
            assert t["observable"] == all(v is not None for v in t["detections"].values())
        n_true += len(true_ids)
        n_all += len(ids)
    assert n_true < 0.95 * 2 * 5 * 10  # some misses
    assert n_all > n_true  # some false alarms


def test_leo_targets_stay_above_20_degrees_and_move_at_orbital_speed() -> None:
    sim = simulate(SimulationConfig(scene="leo", seed=2, targets=4))
    geo = sim.geometry
    for st in geo.stations:
        for f in range(geo.p_job_m.shape[0]):
            assert np.degrees(bearings_of(geo.p_job_m[f], st)[1]).min() >= 20.0
    speed = np.linalg.norm(np.diff(geo.p_job_m, axis=0), axis=2) / np.diff(geo.t_s)[:, None]
    assert np.all((speed > 6800) & (speed < 8000))  # circular LEO speeds seen from the rotating Earth
    assert 200e3 <= np.linalg.norm(geo.stations[1].p_job_m - geo.stations[0].p_job_m) <= 601e3


def test_similar_elevation_scene_is_mostly_ambiguous_and_a_sparse_swarm_is_not() -> None:
    similar = simulate(SimulationConfig(scene="similar-elevation", seed=1))
    swarm = simulate(SimulationConfig(scene="swarm", seed=1, targets=100, frames=3))

    def share(sim_truth: dict) -> float:
        flags = [t["ambiguous"] for f in sim_truth["frames"] for t in f["targets"] if t["observable"]]
        return float(np.mean(flags))

    assert share(similar.truth) > 0.6
    assert share(swarm.truth) < 0.1
