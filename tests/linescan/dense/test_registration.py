"""Frame-to-frame registration: repeatable for a seed (Open3D on one thread while it runs)."""

from __future__ import annotations

import numpy as np
import pytest

from tumblescan import Scanner, Scene, simulate_frames
from tumblescan._open3d import load_open3d
from tumblescan.linescan.dense import registration
from tumblescan.linescan.dense.registration import VOXEL_FRACTION, extent_m, register_consecutive

from ...conftest import motion_for


@pytest.fixture(scope="module")
def frames() -> list[np.ndarray]:
    sim = simulate_frames(motion_for(2, distance_m=50.0), Scene(scanner=Scanner(lines=128, pixels=128)), seed=2)
    return [sim.xyz_m[sim.frame == f] for f in range(5)]


def test_registration_runs_open3d_on_one_thread_and_restores_it(
    frames: list[np.ndarray], monkeypatch: pytest.MonkeyPatch
) -> None:
    o3d = load_open3d()
    o3d.utility.set_max_threads(2)
    seen: list[int] = []
    prepare = registration._prepare

    def spy(*args: object, **kw: object) -> object:
        seen.append(o3d.utility.get_max_threads())
        return prepare(*args, **kw)  # type: ignore[arg-type]

    monkeypatch.setattr(registration, "_prepare", spy)
    register_consecutive(frames, voxel_m=extent_m(frames) * VOXEL_FRACTION, seed=1)
    assert seen and set(seen) == {1}
    assert o3d.utility.get_max_threads() == 2


def test_the_same_frames_register_to_the_same_transforms(frames: list[np.ndarray]) -> None:
    voxel_m = extent_m(frames) * VOXEL_FRACTION
    first, second = (register_consecutive(frames, voxel_m=voxel_m, seed=1) for _ in range(2))
    assert np.array_equal(first.R, second.R) and np.array_equal(first.t, second.t)
