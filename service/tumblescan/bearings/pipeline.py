"""Files in and out, shared by the CLI and the job: simulate to a directory, estimate from an
input file to a result document (and an optional report)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from .._typing import Progress, no_progress
from .estimate import estimate
from .inputs import BearingsInput, Limits, read_input
from .options import EstimateOptions
from .simulate import Simulation, SimulationConfig, invalid_variants, simulate


def write_json(path: Path, doc: Any) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc, allow_nan=False), encoding="utf-8")


def simulate_to(out: Path, config: SimulationConfig) -> Simulation:
    """Write ``input.json``, ``input_noise_free.json``, ``truth.json`` and ``invalid/*.json``."""
    sim = simulate(config)
    write_json(out / "input.json", sim.input)
    write_json(out / "input_noise_free.json", sim.input_noise_free)
    write_json(out / "truth.json", sim.truth)
    fields = {}
    for name, text, field in invalid_variants(sim.input):
        (out / "invalid").mkdir(parents=True, exist_ok=True)
        (out / "invalid" / f"{name}.json").write_text(text, encoding="utf-8")
        fields[name] = field
    write_json(out / "invalid" / "fields.json", fields)
    return sim


def estimate_file(
    path: Path,
    options: EstimateOptions | None = None,
    *,
    limits: Limits | None = None,
    progress: Progress = no_progress,
) -> tuple[BearingsInput, dict[str, Any]]:
    """Read and validate ``path`` (an ``InputError`` when it is bad), then estimate."""
    inp = read_input(path, limits)
    return inp, estimate(inp, options, progress)


def write_report(path: Path, inp: BearingsInput, result: dict[str, Any], *, title: str) -> None:
    from .report import build_report

    path.write_text(build_report(inp, result, title=title), encoding="utf-8")
