"""``tumblescan bearings simulate | estimate``: many targets from two bearings-only stations."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .common import input_errors

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
        f"wrote {out}/input.json ({sim.truth['targets']} targets, {len(sim.input['frames'])} frames, {n} detections), input_noise_free.json, truth.json, invalid/"
    )
