"""``tumblescan marker-pose-graph simulate | estimate``."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Literal

import typer

from .common import check_output_files, input_errors

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
    level: Annotated[
        Literal["A", "B", "C"],
        typer.Option(help="A: 3D marker coordinates; B: tag corner detections; C: tag images (a zip)"),
    ] = "A",
    target: Annotated[
        Literal["kite", "box"] | None, typer.Option(help="level A only (default kite); B and C: the tagged box")
    ] = None,
    motion: Annotated[Literal["paper", "tumble"], typer.Option()] = "paper",
    frames: Annotated[
        int | None, typer.Option(min=3, max=200_000, help="default: 500 (A, B), 20 (C); level A: at least 10")
    ] = None,
    layout: Annotated[
        bool | None, typer.Option("--layout/--no-layout", help="level A only: include the layout (default: yes)")
    ] = None,
) -> None:
    """Simulate the paper's 4-camera rig: writes markers.json (A), tags.json (B) or images.zip (C),
    and truth.json."""
    from ..errors import InputError
    from ..marker_pose.pipeline import write_simulation, write_tag_simulation
    from ..marker_pose.simulate import SimConfig
    from ..marker_pose.tag_simulate import TagSimConfig

    if level != "A":  # levels B and C simulate the tagged box, always with its tag layout
        for flag, name, value in (("--target", "target", target), ("--layout/--no-layout", "layout", layout)):
            if value is not None:
                raise InputError(f"{flag} applies to level A only (levels B and C: the tagged box)", field=name)
    if level == "A":
        config = SimConfig(
            target=target or "kite", motion=motion, frames=frames or 500, with_layout=layout is not False
        )
        written, truth = write_simulation(out, config, seed)
    elif level == "B":
        written, truth = write_tag_simulation(out, TagSimConfig(motion=motion, frames=frames or 500), seed)
    else:
        from ..marker_pose.tag_render import image_config, write_image_simulation

        written, truth = write_image_simulation(out, image_config(motion=motion, frames=frames or 20), seed)
    typer.echo(f"wrote {written} and {truth}")


# The input form each flag of estimate belongs to (as the API's options), beyond the shared ones.
FORMS = {"A": "markers", "B": "tags", "C": "images"}
FLAG_FORMS = {
    "--layout": ("markers",),
    "--method": ("markers",),
    "--body-frame": ("markers",),
    "--point-sigma-m": ("markers",),
    "--pixel-sigma-px": ("tags", "images"),
    "--detector": ("images",),
}


@app.command()
@input_errors
def estimate(
    markers: Annotated[
        Path,
        typer.Argument(
            help="markers JSON (tumblescan.markers.v1) or CSV (level A), tags JSON (tumblescan.tags.v1, level B), "
            "or a zip or directory of images with scene.json (level C); the level is read from the content"
        ),
    ],
    layout: Annotated[Path | None, typer.Option(help="level A: layout JSON {markers: [{id, xyz}]}")] = None,
    method: Annotated[Literal["graph", "paper"] | None, typer.Option(help="level A only (default graph)")] = None,
    motion_prior: Annotated[Literal["none", "constant_velocity"], typer.Option()] = "none",
    body_frame: Annotated[Literal["layout", "launch"] | None, typer.Option(help="level A only")] = None,
    point_sigma_m: Annotated[float | None, typer.Option(help="level A only")] = None,
    pixel_sigma_px: Annotated[float | None, typer.Option(help="levels B and C: corner sigma [px]")] = None,
    detector: Annotated[
        Literal["apriltag", "aruco"] | None, typer.Option(help="level C only (default apriltag)")
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="print only the result JSON")] = False,
    report: Annotated[Path | None, typer.Option(help="write an HTML report here")] = None,
) -> None:
    """Estimate every frame's pose; --json prints exactly one JSON document."""
    from ..errors import InputError
    from ..marker_pose.options import ImagePoseOptions, MarkerPoseOptions, TagPoseOptions
    from ..marker_pose.pipeline import input_level, run, run_tags

    check_output_files(report=report)
    level = input_level(markers)
    form = FORMS[level]
    given = {
        "--layout": layout,
        "--method": method,
        "--body-frame": body_frame,
        "--point-sigma-m": point_sigma_m,
        "--pixel-sigma-px": pixel_sigma_px,
        "--detector": detector,
    }
    for flag, value in given.items():  # refused by name, never ignored (the API's 422 says the same)
        if value is not None and form not in FLAG_FORMS[flag]:
            others = " and ".join(FLAG_FORMS[flag])
            raise InputError(
                f"{flag}: does not apply to {form} input (an option of {others} input)",
                field=flag.lstrip("-").replace("-", "_"),
            )
    if level == "A":
        options = MarkerPoseOptions(
            method=method or "graph", motion_prior=motion_prior, body_frame=body_frame, point_sigma_m=point_sigma_m
        )
        result = run(markers, layout=layout, options=options)
    elif level == "B":
        result = run_tags(markers, options=TagPoseOptions(motion_prior=motion_prior, pixel_sigma_px=pixel_sigma_px))
    else:
        from ..marker_pose.pipeline import run_images

        opts = ImagePoseOptions(
            motion_prior=motion_prior, pixel_sigma_px=pixel_sigma_px, detector=detector or "apriltag"
        )
        result = run_images(markers, options=opts)
    if report is not None:
        from ..marker_pose.report import build_report

        report.write_text(build_report(result, f"marker-pose-graph: {markers.name}"))
    if as_json:
        sys.stdout.write(result.model_dump_json() + "\n")
        return
    measured = sum(p.status == "measured" for p in result.poses)
    bridged = sum(p.status == "bridged" for p in result.poses)
    from ..marker_pose.report import pose_text, residual_text

    typer.echo(
        f"level {result.level}: {len(result.poses)} frames, {measured} measured (coverage {result.coverage:.3f}), "
        f"{bridged} bridged, residual RMS {residual_text(result)}, layout {result.layout.source} "
        f"({len(result.layout.markers)} {'tags' if result.level != 'A' else 'markers'}), "
        f"{result.graph.iterations} iterations"
    )
    for line in pose_text(result):
        typer.echo(line)
    for w in result.warnings:
        typer.echo(f"warning: {w}")
