"""Files in and out, shared by the CLI and the job: simulate to a directory, estimate from an
input file to a result document (and an optional report)."""

from __future__ import annotations

import json
import os
import uuid
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


def write_outputs(
    inp: BearingsInput, result: dict[str, Any], *, out: Path | None, report: Path | None, title: str
) -> None:
    """Write the result JSON to ``out`` and the report to ``report`` (either may be None): both
    texts are made first, then written beside their targets and renamed into place, so a report
    that fails (to render, or on a full disk) leaves no result behind it. Only a rename failing
    after the first succeeded (the second target's directory lost meanwhile) leaves one of them.
    The directories must exist (the CLI checks them before the work); none is created. An
    ``OSError`` names the target that failed (``filename``), not the temporary file."""
    texts: list[tuple[Path, str]] = []
    if out is not None:
        texts.append((out, json.dumps(result, allow_nan=False)))
    if report is not None:
        from .report import build_report

        texts.append((report, build_report(inp, result, title=title)))
    staged: list[tuple[Path, Path]] = []
    try:
        for path, text in texts:
            # Opened like any new file (mode "x", so the umask sets its permissions), under a
            # name no other run picks (short, so a long target name still leaves room).
            tmp = path.with_name(f".{path.name[:40]}.{uuid.uuid4().hex[:12]}.part")
            try:
                with tmp.open("x", encoding="utf-8") as f:
                    staged.append((tmp, path))
                    f.write(text)
            except OSError as exc:
                raise OSError(exc.errno, exc.strerror, str(path)) from exc
        for tmp, path in staged:
            try:
                os.replace(tmp, path)
            except OSError as exc:
                raise OSError(exc.errno, exc.strerror, str(path)) from exc
    finally:
        for tmp, _ in staged:
            tmp.unlink(missing_ok=True)
