"""Shared fixtures: seeded simulations of the paper's satellite on the paper's motion grid."""

from __future__ import annotations

import numpy as np
import pytest

from tumblescan import Motion, Scanner, Scene, Tracks, random_motion, simulate_tracks


def motion_for(seed: int, **kw: object) -> Motion:
    return random_motion(np.random.default_rng(seed), **kw)  # type: ignore[arg-type]


def tracks_for(seed: int, *, noise: bool = True, **scene_kw: object) -> tuple[Motion, Tracks]:
    motion = motion_for(seed)
    tracks, _ = simulate_tracks(motion, Scene(noise=noise, **scene_kw), seed=seed)
    return motion, tracks


@pytest.fixture(scope="session")
def small_scanner() -> Scanner:
    """A coarse scanner (64 x 64) so dense-frame tests stay quick."""
    return Scanner(lines=64, pixels=64)
