"""Small seeded sequences (256 px, so the suite runs in seconds), written once per session."""

from __future__ import annotations

from pathlib import Path

import pytest

from tumblescan.spin_rate.options import EstimateOptions
from tumblescan.spin_rate.pipeline import load_input, run
from tumblescan.spin_rate.result import SpinResult
from tumblescan.spin_rate.simulate import simulate_sequence, write_sequence

WIDTH_PX = 256


def _write(root: Path, seed: int, kind: str, noise: bool = False, **kw: object) -> Path:
    out = root / f"{kind}_{seed}_{int(noise)}"
    write_sequence(out, simulate_sequence(seed, kind, noises=(noise,), width_px=WIDTH_PX, **kw))  # type: ignore[arg-type]
    return out


@pytest.fixture(scope="session")
def sims(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("spin")


@pytest.fixture(scope="session")
def los_seq(sims: Path) -> Path:
    return _write(sims, 3, "los")


@pytest.fixture(scope="session")
def static_seq(sims: Path) -> Path:
    return _write(sims, 5, "static", noise=True)


@pytest.fixture(scope="session")
def blank_seq(sims: Path) -> Path:
    return _write(sims, 1, "blank", noise=True)


@pytest.fixture(scope="session")
def corrupt_seq(sims: Path) -> Path:
    return _write(sims, 3, "corrupt")


@pytest.fixture(scope="session")
def los_result(los_seq: Path) -> SpinResult:
    """One estimate of ``los_seq`` with its tracks, for tests of what is made of a result."""
    return run(load_input(los_seq / "meta.json"), EstimateOptions(return_tracks=True))
