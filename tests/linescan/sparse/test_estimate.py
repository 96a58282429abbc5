"""Seeded round trips: simulate -> estimate -> compare with the truth."""

from __future__ import annotations

import numpy as np
import pytest

from tumblescan import EstimateOptions, Motion, Scene, SwarmConfig, Tracks, estimate_motion, simulate_tracks
from tumblescan.errors import InvalidOptionError
from tumblescan.linescan.truth import errors_against

from ...conftest import motion_for, tracks_for


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_noise_free_tracks_give_the_motion_to_rounding_level(seed: int) -> None:
    motion, tracks = tracks_for(seed, noise=False)
    result = estimate_motion(tracks)
    err = errors_against(result, motion)
    assert result.model == "spin-precession"
    assert all(abs(v) < 1e-9 for v in err.values()), err
    assert result.validation.passed and result.validation.test == "fixed"
    assert result.validation.distance is not None and result.validation.distance < 1e-3
    assert result.fit.rms_residual_m < 1e-9
    assert result.warnings == []


@pytest.mark.parametrize("seed", [10, 11, 12])
def test_noisy_tracks_are_within_five_sigma_of_the_truth(seed: int) -> None:
    motion, tracks = tracks_for(seed)
    r = estimate_motion(tracks)
    err = errors_against(r, motion)
    u = r.uncertainty
    assert r.model == "spin-precession" and r.validation.passed and r.validation.test == "covariance"
    assert abs(err["spin_axis_deg"]) < 5 * u.spin_axis_deg
    assert abs(err["spin_rate_deg_s"]) < 5 * u.spin_rate_deg_s
    assert u.precession_axis_deg is not None and abs(err["precession_axis_deg"]) < 5 * u.precession_axis_deg
    assert abs(err["precession_rate_deg_s"]) < 5 * u.precession_rate_deg_s
    assert err["center_m"] < 5 * float(np.linalg.norm(u.center_m))
    # Sigmas are those of 2 cm / 36 arcsec data: small but not zero.
    assert 1e-4 < u.spin_rate_deg_s < 1.0
    assert 0.01 < r.fit.rms_residual_m < 0.05


def test_swarm_path_and_each_variant_reach_the_global_minimum() -> None:
    motion, tracks = tracks_for(4, noise=False)
    for variant in ("pso", "tvac", "apso", "naiwpso"):
        opts = EstimateOptions(strategy="swarm", swarm=SwarmConfig(variant=variant), seed=1)
        r = estimate_motion(tracks, opts)
        assert r.solver.path == f"swarm({variant})+lm"
        assert max(abs(v) for v in errors_against(r, motion).values()) < 1e-9, variant


def test_pairwise_objective_reaches_the_truth_on_noise_free_data() -> None:
    motion, tracks = tracks_for(5, noise=False)
    r = estimate_motion(tracks, EstimateOptions(objective="pairwise"))
    assert max(abs(v) for v in errors_against(r, motion).values()) < 1e-9


def test_same_seed_same_result() -> None:
    _, tracks = tracks_for(6)
    opts = EstimateOptions(strategy="swarm", seed=42)
    a, b = estimate_motion(tracks, opts), estimate_motion(tracks, opts)
    assert a.spin == b.spin and a.precession == b.precession and a.uncertainty == b.uncertainty


def test_pure_spin_falls_back_to_spin_only_and_reports_nothing_unobservable() -> None:
    motion = Motion.from_degrees(spin_axis=(0.3, -0.5, 0.8), spin_rate_deg_s=25, center_m=(0.2, -0.1, 50))
    tracks, _ = simulate_tracks(motion, Scene(), seed=7)
    r = estimate_motion(tracks)
    assert r.model == "spin-only"
    assert r.precession.axis is None and r.precession.alpha_deg is None and r.nutation_angle_deg is None
    assert r.uncertainty.precession_axis_deg is None
    assert r.precession.rate_deg_s == 0.0
    assert any("spin-only model" in w and "unobservable" in w for w in r.warnings)
    err = errors_against(r, motion)
    assert abs(err["spin_rate_deg_s"]) < 5 * r.uncertainty.spin_rate_deg_s
    assert abs(err["spin_axis_deg"]) < 5 * r.uncertainty.spin_axis_deg
    # The centre reported is on the spin axis (the truth's centre is too).
    assert err["center_m"] < 5 * float(np.linalg.norm(r.uncertainty.center_m))


def test_parallel_axes_are_reported_as_spin_only_with_the_summed_rate() -> None:
    axis = np.array([0.2, 0.4, 0.9])
    motion = Motion.from_degrees(
        spin_axis=axis, spin_rate_deg_s=20, precession_axis=axis, precession_rate_deg_s=6, center_m=(0, 0, 50)
    )
    tracks, _ = simulate_tracks(motion, Scene(noise=False), seed=3)
    r = estimate_motion(tracks)
    assert r.model == "spin-only"
    assert r.spin.rate_deg_s == pytest.approx(26.0, abs=1e-6)
    assert any("sum of both rates" in w for w in r.warnings)


def test_strong_precession_is_not_mistaken_for_spin_only() -> None:
    # A slow precession (1 deg/s) in noisy data is still significant over 15 frames.
    motion = motion_for(8, precession_rate_deg_s=(1.0, 1.0))
    tracks, _ = simulate_tracks(motion, Scene(), seed=8)
    assert estimate_motion(tracks).model == "spin-precession"


def test_outliers_are_rejected_and_counted() -> None:
    motion, tracks = tracks_for(9)
    xyz = tracks.xyz_m.copy()
    bad = np.array([5, 40, 77])
    xyz[bad] += np.array([0.8, -0.5, 1.0])  # metres: gross mismatches
    corrupted = Tracks(tracks.track_ids, tracks.track, tracks.t_s, xyz, tracks.frame, tracks.sensor)
    r = estimate_motion(corrupted)
    assert r.fit.outliers == 3 and r.fit.observations == len(tracks)
    assert any("3 observation(s) rejected" in w for w in r.warnings)
    err = errors_against(r, motion)
    assert abs(err["spin_rate_deg_s"]) < 5 * r.uncertainty.spin_rate_deg_s


def test_reference_time_option_moves_the_reported_spin_axis() -> None:
    motion, tracks = tracks_for(1, noise=False)
    r = estimate_motion(tracks, EstimateOptions(reference_time_s=3.0))
    assert r.reference_time_s == 3.0
    assert np.allclose(r.spin.axis, motion.spin_axis_at(3.0), atol=1e-9)


@pytest.mark.parametrize("reference_time_s", [1e300, -1e6])
def test_a_reference_time_far_from_the_observations_is_an_option_error(reference_time_s: float) -> None:
    # 1e300 once ended as internal_error (LinAlgError: SVD did not converge), 1e6 as a long run
    # that failed its own validation.
    _, tracks = tracks_for(1)
    with pytest.raises(InvalidOptionError, match="too far from the observations") as err:
        estimate_motion(tracks, EstimateOptions(reference_time_s=reference_time_s))
    assert err.value.field == "options.reference_time_s"


def test_a_bad_validation_frame_count_is_an_option_error() -> None:
    _, tracks = tracks_for(1)
    with pytest.raises(InvalidOptionError, match="validation_frames"):
        estimate_motion(tracks, EstimateOptions(validation_frames=15))


def test_four_frames_estimate_but_cannot_validate() -> None:
    motion, tracks = tracks_for(2, noise=False, frames=4)
    r = estimate_motion(tracks)
    assert max(abs(v) for v in errors_against(r, motion).values()) < 1e-6
    assert not r.validation.passed and r.validation.test == "skipped"
    assert any("two-frame-count check needs" in w for w in r.warnings)
