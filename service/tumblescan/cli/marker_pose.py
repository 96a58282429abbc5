"""``tumblescan marker-pose-graph simulate | estimate``."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Literal

import typer

from .common import input_errors

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="marker-pose-graph: target pose from tracked markers (SE(3) pose graph).",
)


@app.command()
@input_errors
def simulate(
    out: Annotated[Path, typer.Option(help="output directory")] = Path("sim-markers"),
    seed: Annotated[int, typer.Option(min=0)] = 0,
    level: Annotated[Literal["A"], typer.Option(help="A: 3D marker coordinates (B and C later)")] = "A",
    target: Annotated[Literal["kite", "box"], typer.Option()] = "kite",
    motion: Annotated[Literal["paper", "tumble"], typer.Option()] = "paper",
    frames: Annotated[int, typer.Option(min=10, max=200_000)] = 500,
    layout: Annotated[bool, typer.Option(help="include the layout (body.markers)")] = True,
) -> None:
    """Simulate the paper's 4-camera rig: writes markers.json and truth.json."""
    from ..marker_pose.pipeline import write_simulation
    from ..marker_pose.simulate import SimConfig

    config = SimConfig(target=target, motion=motion, frames=frames, with_layout=layout)
    markers, truth = write_simulation(out, config, seed)
    typer.echo(f"wrote {markers} and {truth}")


@app.command()
@input_errors
def estimate(
    markers: Annotated[Path, typer.Argument(help="markers JSON (tumblescan.markers.v1) or CSV")],
    layout: Annotated[Path | None, typer.Option(help="layout JSON {markers: [{id, xyz}]}")] = None,
    method: Annotated[Literal["graph", "paper"], typer.Option()] = "graph",
    motion_prior: Annotated[Literal["none", "constant_velocity"], typer.Option()] = "none",
    body_frame: Annotated[Literal["layout", "launch"] | None, typer.Option()] = None,
    point_sigma_m: Annotated[float | None, typer.Option()] = None,
    as_json: Annotated[bool, typer.Option("--json", help="print only the result JSON")] = False,
    report: Annotated[Path | None, typer.Option(help="write an HTML report here")] = None,
) -> None:
    """Estimate every frame's pose; --json prints exactly one JSON document."""
    from ..marker_pose.options import MarkerPoseOptions
    from ..marker_pose.pipeline import run

    options = MarkerPoseOptions(
        method=method, motion_prior=motion_prior, body_frame=body_frame, point_sigma_m=point_sigma_m
    )
    result = run(markers, layout=layout, options=options)
    if report is not None:
        from ..marker_pose.report import build_report

        report.write_text(build_report(result, f"marker-pose-graph: {markers.name}"))
    if as_json:
        sys.stdout.write(result.model_dump_json() + "\n")
        return
    measured = sum(p.status == "measured" for p in result.poses)
    bridged = sum(p.status == "bridged" for p in result.poses)
    typer.echo(
        f"{len(result.poses)} frames, {measured} measured (coverage {result.coverage:.3f}), {bridged} bridged, "
        f"residual RMS {1000 * result.residuals.rms_m:.2f} mm, layout {result.layout.source} "
        f"({len(result.layout.markers)} markers), graph {result.graph.iterations} iterations"
    )
    for w in result.warnings:
        typer.echo(f"warning: {w}")
