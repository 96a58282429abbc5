"""Seeded simulated views, rendered once per session at 640x480 so the tests stay quick."""

from __future__ import annotations

from pathlib import Path

import pytest

from tumblescan.panel_axis.simulate import simulate_view, write_view

SIZE = {"width_px": 640, "height_px": 480}


def view_dir(factory: pytest.TempPathFactory, name: str, seed: int, **kw: object) -> Path:
    out = factory.mktemp(name)
    write_view(out, simulate_view(seed, **SIZE, **kw))  # type: ignore[arg-type]
    return out


@pytest.fixture(scope="session")
def near_clean(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return view_dir(tmp_path_factory, "near_clean", 7, regime="near", noise=False)


@pytest.fixture(scope="session")
def near_noisy(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return view_dir(tmp_path_factory, "near_noisy", 9, regime="near", noise=True)


@pytest.fixture(scope="session")
def ground(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return view_dir(tmp_path_factory, "ground", 4, regime="ground", noise=True)


@pytest.fixture(scope="session")
def near_bus_across(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A near view whose longest family across the axis is the bus's, not the wing's ends."""
    return view_dir(tmp_path_factory, "near_bus_across", 1057, regime="near", noise=True)


@pytest.fixture(scope="session")
def ground_roots_hidden(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A ground view with both wings' roots hidden behind the bus."""
    return view_dir(tmp_path_factory, "ground_roots_hidden", 1004, regime="ground", noise=True)
