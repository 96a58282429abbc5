"""``tumblescan bearings simulate | estimate``: many targets from two bearings-only stations."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from .common import check_output_files, input_errors, json_stdout, options_from_flags

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="bearings: many targets located from two infrared stations' bearings.",
)


@app.command()
@input_errors
def simulate(
    out: Annotated[Path, typer.Option(help="output directory")] = Path("sim-bearings"),
    seed: Annotated[int, typer.Option(min=0)] = 0,
    scene: Annotated[
        str,
        typer.Option(help="paper, close, near-collinear, baseline-plane, similar-elevation, swarm or leo"),
    ] = "paper",
    targets: Annotated[int | None, typer.Option(min=1, max=5000, help="default: the scene's")] = None,
    frames: Annotated[int, typer.Option(min=1, max=1000)] = 10,
    clutter: Annotated[
        float, typer.Option(min=0.0, max=10.0, help="false alarms per station and frame, per target")
    ] = 0.0,
    p_miss: Annotated[float, typer.Option(min=0.0, max=0.99, help="probability of a missed detection")] = 0.0,
) -> None:
    """Simulate a scene: writes input.json, input_noise_free.json, truth.json and invalid/*.json."""
    from ..bearings.pipeline import simulate_to
    from ..bearings.scenes import SCENES
    from ..bearings.simulate import SimulationConfig

    if scene not in SCENES:
        raise typer.BadParameter(f"unknown scene {scene!r}; one of {', '.join(SCENES)}", param_hint="--scene")
    config = SimulationConfig(scene=scene, seed=seed, targets=targets, frames=frames, clutter=clutter, p_miss=p_miss)
    sim = simulate_to(out, config)
    n = sum(len(v) for fr in sim.input["frames"] for v in fr["detections"].values())
    typer.echo(
        f"wrote {out}/input.json ({sim.truth['targets']} targets, {len(sim.input['frames'])} frames, "
        f"{n} detections), input_noise_free.json, truth.json, invalid/"
    )


@app.command()
@input_errors
def estimate(
    input_file: Annotated[Path, typer.Argument(help="tumblescan.bearings.input/1 JSON")],
    as_json: Annotated[bool, typer.Option("--json", help="print only the result JSON on stdout")] = False,
    method: Annotated[str, typer.Option(help="ml (recommended) or paper (the paper's method, for comparison)")] = "ml",
    gate_chi2: Annotated[
        float | None, typer.Option(help="ml only: chi-square gate on a pair (1 dof); 16 when not given")
    ] = None,
    tracks: Annotated[bool, typer.Option(help="link targets into tracks across frames")] = True,
    out: Annotated[Path | None, typer.Option(help="also write the result JSON here")] = None,
    report: Annotated[Path | None, typer.Option(help="write the HTML report here")] = None,
) -> None:
    """Associate, locate and link the targets seen by two bearings-only stations."""
    import json
    import sys

    from ..bearings.result import failure_document
    from ..bearings.text import summary_text
    from ..errors import InputError

    # Every refusal, of an option as of the input, is an InputError here, so that with --json
    # each one prints the failure document on stdout, as the contract says.
    try:
        with json_stdout(as_json):
            result = _estimate(input_file, method, gate_chi2, tracks, out, report)
    except InputError as exc:
        if as_json:
            sys.stdout.write(json.dumps(failure_document(exc.code, str(exc), exc.field)) + "\n")
        raise
    if as_json:
        sys.stdout.write(json.dumps(result) + "\n")
        return
    typer.echo(summary_text(result))


# The CLI's flag for each option it passes on, to name it in a refusal.
FLAGS = {"method": "--method", "gate_chi2": "--gate-chi2", "link_tracks": "--tracks/--no-tracks"}


def _estimate(
    input_file: Path, method: str, gate_chi2: float | None, tracks: bool, out: Path | None, report: Path | None
) -> dict[str, Any]:
    """Check the options, the output paths and the input file before any work (so a refusal
    has written nothing), then estimate and write the outputs, both made before either is written."""
    from ..bearings.options import EstimateOptions
    from ..bearings.pipeline import estimate_file, write_outputs
    from ..errors import InputError

    # The options model is the one source of the bounds (NaN and Infinity included): a flag
    # not given is left out, so it is neither checked against the method nor stored as given.
    given: dict[str, Any] = {"method": method, "link_tracks": tracks}
    if gate_chi2 is not None:
        given["gate_chi2"] = gate_chi2
    options = options_from_flags(EstimateOptions, given, flags=FLAGS)
    check_output_files(out=out, report=report)
    if input_file.is_dir():
        raise InputError(f"{input_file} is a directory, not a file", field="input")
    if not input_file.exists():
        raise InputError(f"no such file: {input_file}", field="input")
    try:
        inp, result = estimate_file(input_file, options)
    except OSError as exc:  # unreadable: permission denied, an I/O error
        raise InputError(f"{input_file}: {exc.strerror or exc}", field="input") from None
    try:
        write_outputs(inp, result, out=out, report=report, title=f"Bearings: {input_file.name}")
    except OSError as exc:  # a full disk, a directory denied: neither output is left half-way
        name = "out" if out is not None and exc.filename == str(out) else "report"
        raise InputError(f"--{name}: cannot write {exc.filename} ({exc.strerror or exc})", field=name) from None
    return result
