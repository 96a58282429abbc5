"""Shared fixtures: seeded simulations of the paper's satellite on the paper's motion grid."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest

from tumblescan import Motion, Scanner, Scene, Tracks, random_motion, simulate_tracks

if TYPE_CHECKING:
    from fastapi.testclient import TestClient


def motion_for(seed: int, **kw: object) -> Motion:
    return random_motion(np.random.default_rng(seed), **kw)  # type: ignore[arg-type]


def tracks_for(seed: int, *, noise: bool = True, **scene_kw: object) -> tuple[Motion, Tracks]:
    motion = motion_for(seed)
    tracks, _ = simulate_tracks(motion, Scene(noise=noise, **scene_kw), seed=seed)
    return motion, tracks


# The test under way, for `make test` to name when the process dies of a signal (a C library's
# abort): faulthandler's stack of pytest's own frames fills the tail of a CI log and hides it.
RUNNING = Path(__file__).resolve().parents[1] / ".pytest-running"


def pytest_runtest_logstart(nodeid: str) -> None:
    RUNNING.write_text(nodeid + "\n")


def pytest_sessionfinish() -> None:
    RUNNING.unlink(missing_ok=True)


@pytest.fixture(autouse=True)
def _thread_pool_variables() -> Iterator[None]:
    """Each test leaves the BLAS/OpenMP sizes in ``os.environ`` as it found them: ``serve`` and
    ``worker`` run in-process size them for their workers (``cli.service.share_cores``), and a
    later test would inherit that (``numerics.parallel`` reads ``OMP_NUM_THREADS``: a leaked 2 let a
    job's queue worker try a process pool, which a daemonic process may not start)."""
    from tumblescan.cli.service import THREAD_POOL_VARS

    saved = {var: os.environ.get(var) for var in THREAD_POOL_VARS}
    yield
    for var, value in saved.items():
        if value is None:
            os.environ.pop(var, None)
        else:
            os.environ[var] = value


@pytest.fixture(scope="session")
def small_scanner() -> Scanner:
    """A coarse scanner (64 x 64) so dense-frame tests stay quick."""
    return Scanner(lines=64, pixels=64)


@pytest.fixture(scope="module")
def api(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    """The API in-process, without workers: enough for everything checked before a job runs."""
    from fastapi.testclient import TestClient

    from tumblescan.api.app import create_app
    from tumblescan.settings import Settings

    with TestClient(create_app(Settings(data_dir=tmp_path_factory.mktemp("api") / "data"))) as c:
        yield c
