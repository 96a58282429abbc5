from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tumblescan import Scanner, Scene, distort, estimate_motion, rectify, simulate_frames, simulate_tracks
from tumblescan.errors import NonFiniteValueError

from ..conftest import motion_for


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000), target=st.floats(-5, 20))
def test_rectify_then_distort_is_identity(seed: int, target: float) -> None:
    motion = motion_for(seed % 50)
    rng = np.random.default_rng(seed)
    xyz = rng.normal(size=(500, 3)) * 5 + [0, 0, 50]
    t = rng.uniform(0, 15, 500)
    at_target = rectify(xyz, t, motion, to_time_s=target)
    assert np.allclose(distort(at_target, t, motion, from_time_s=target), xyz, atol=1e-9)


def test_rectifying_noise_free_frames_with_the_true_motion_recovers_the_reference(small_scanner: Scanner) -> None:
    motion = motion_for(4)
    cloud = simulate_frames(motion, Scene(scanner=small_scanner, frames=5, noise=False), seed=4)
    rect = rectify(cloud.xyz_m, cloud.t_s, motion, to_time_s=motion.reference_time_s)
    assert np.max(np.linalg.norm(rect - cloud.reference_m, axis=1)) < 1e-9


def test_rectifying_with_an_estimated_motion_removes_the_distortion(small_scanner: Scanner) -> None:
    motion = motion_for(6)
    scene = Scene(scanner=small_scanner, frames=15)
    tracks, _ = simulate_tracks(motion, scene, seed=6)
    result = estimate_motion(tracks)
    cloud = simulate_frames(motion, scene, seed=6)
    T = result.reference_time_s
    est = rectify(cloud.xyz_m, cloud.t_s, result.motion(), to_time_s=T)
    true = rectify(cloud.xyz_m, cloud.t_s, motion, to_time_s=T)
    raw_error = np.linalg.norm(cloud.xyz_m - true, axis=1).mean()
    motion_error = np.linalg.norm(est - true, axis=1).mean()
    # Unrectified points are metres away; the estimate's error is centimetres.
    assert raw_error > 1.0
    assert motion_error < 0.05


def test_rectify_rejects_nan_and_bad_shapes() -> None:
    motion = motion_for(0)
    with pytest.raises(NonFiniteValueError):
        rectify([[0, 0, np.nan]], [0.0], motion)
    with pytest.raises(ValueError, match="xyz_m"):
        rectify([[0, 0]], [0.0], motion)
