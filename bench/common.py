"""Shared helpers for the benchmarks: scenarios on the paper's grid, tables, output folder."""

from __future__ import annotations

import os
import platform
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from tumblescan import Motion, Scene, Tracks, random_motion, simulate_tracks

OUT = Path(__file__).resolve().parent / "out"


def out_dir() -> Path:
    OUT.mkdir(parents=True, exist_ok=True)
    return OUT


def scenario(seed: int, *, noise: bool, scene: Scene | None = None) -> tuple[Motion, Tracks]:
    """Motion on the paper's grid (w_s 15-37, w_p 3-14 deg/s, random axes) and its tracks."""
    motion = random_motion(np.random.default_rng(seed))
    tracks, _ = simulate_tracks(motion, scene or Scene(noise=noise), seed=seed)
    return motion, tracks


def table(rows: Sequence[Sequence[object]], header: Sequence[str]) -> str:
    cells = [[str(h) for h in header]] + [[_fmt(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    lines = ["  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def machine() -> str:
    return f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"


def _fmt(c: object) -> str:
    if isinstance(c, float):
        return f"{c:.3g}"
    return str(c)
