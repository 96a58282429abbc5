"""``tumblescan bearings simulate | estimate``: many targets from two bearings-only stations."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .common import input_errors, json_stdout

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
    gate_chi2: Annotated[float, typer.Option(min=0.1, max=1000.0, help="chi-square gate on a pair (1 dof)")] = 16.0,
    tracks: Annotated[bool, typer.Option(help="link targets into tracks across frames")] = True,
    out: Annotated[Path | None, typer.Option(help="also write the result JSON here")] = None,
    report: Annotated[Path | None, typer.Option(help="write the HTML report here")] = None,
) -> None:
    """Associate, locate and link the targets seen by two bearings-only stations."""
    import json
    import sys

    from ..bearings.options import EstimateOptions
    from ..bearings.pipeline import estimate_file, write_json, write_report
    from ..bearings.result import failure_document
    from ..errors import InputError

    if method not in ("ml", "paper"):
        raise typer.BadParameter(f"{method!r} is not 'ml' or 'paper'", param_hint="--method")
    options = EstimateOptions(method=method, gate_chi2=gate_chi2, link_tracks=tracks)
    try:
        with json_stdout(as_json):
            inp, result = estimate_file(input_file, options)
            if out is not None:
                write_json(out, result)
            if report is not None:
                write_report(report, inp, result, title=f"Bearings: {input_file.name}")
    except InputError as exc:
        if as_json:
            sys.stdout.write(json.dumps(failure_document(exc.code, str(exc), exc.field)) + "\n")
        raise
    if as_json:
        sys.stdout.write(json.dumps(result) + "\n")
        return
    s = result["summary"]
    typer.echo(
        f"{s['targets']} targets in {len(result['frames'])} frames ({s['ambiguous']} ambiguous, {s['tracks']} tracks); "
        f"unassociated detections: {', '.join(f'{k} {v}' for k, v in s['unassociated'].items())}; "
        f"{result['timings_ms']['total']:.0f} ms"
    )
