"""Files in, files out: read the markers (and an optional layout), estimate, write result.json
(and an HTML report). Shared by the CLI and the job."""

from __future__ import annotations

import json
from pathlib import Path

from .._typing import Progress, no_progress
from .estimate import estimate_poses
from .markers_io import MarkerInput, read_markers
from .options import MarkerPoseLimits, MarkerPoseOptions
from .result import MarkerPoseResult
from .simulate import SimConfig, simulate


def load_input(
    markers: Path,
    layout: Path | None = None,
    options: MarkerPoseOptions | None = None,
    limits: MarkerPoseLimits | None = None,
) -> MarkerInput:
    """Read and validate (every refusal is an ``InputError`` naming the field)."""
    options = options or MarkerPoseOptions()
    return read_markers(markers, layout_path=layout, point_sigma_m=options.point_sigma_m, limits=limits)


def run(
    markers: Path,
    *,
    layout: Path | None = None,
    options: MarkerPoseOptions | None = None,
    limits: MarkerPoseLimits | None = None,
    progress: Progress = no_progress,
) -> MarkerPoseResult:
    options = options or MarkerPoseOptions()
    data = load_input(markers, layout, options, limits)
    return estimate_poses(data, options, progress)


def write_simulation(out: Path, config: SimConfig, seed: int) -> tuple[Path, Path]:
    """Simulate and write markers.json and truth.json into ``out``."""
    sim = simulate(config, seed)
    out.mkdir(parents=True, exist_ok=True)
    (out / "markers.json").write_text(json.dumps(sim.document()))
    truth = sim.truth()
    truth["seed"] = seed
    (out / "truth.json").write_text(json.dumps(truth))
    return out / "markers.json", out / "truth.json"
