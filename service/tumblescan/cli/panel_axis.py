"""``tumblescan panel-axis simulate | estimate``: the solar-panel axis from one optical image."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Literal

import typer

from .common import input_errors, json_stdout

app = typer.Typer(
    add_completion=False, no_args_is_help=True, help="panel-axis: a solar-panel axis from one optical image."
)


@app.command()
@input_errors
def simulate(
    out: Annotated[Path, typer.Option(help="output directory")] = Path("panel-sim"),
    seed: Annotated[int, typer.Option(min=0)] = 0,
    regime: Annotated[
        Literal["near", "ground"], typer.Option(help="near range, or a ground telescope (weak perspective)")
    ] = "near",
    noise: Annotated[bool, typer.Option(help="shot and read noise")] = True,
    case: Annotated[
        Literal["normal", "edge-on", "end-on", "blank", "broken-meta"], typer.Option(help="the view to make")
    ] = "normal",
    width_px: Annotated[int, typer.Option(min=64, max=8192)] = 1024,
    height_px: Annotated[int, typer.Option(min=64, max=8192)] = 768,
    bits: Annotated[int | None, typer.Option(help="8 or 16 (default: 8 near, 16 ground)")] = None,
    tiff: Annotated[bool, typer.Option(help="write image.tif instead of image.png")] = False,
) -> None:
    """Render a box-bus satellite with two wings: writes the image, meta.json and truth.json."""
    from ..panel_axis.simulate import simulate_view, write_view

    if bits not in (None, 8, 16):
        raise typer.BadParameter("--bits must be 8 or 16")
    view = simulate_view(
        seed, regime, noise=noise, case=case, width_px=width_px, height_px=height_px, bits=bits,
        image_name="image.tif" if tiff else "image.png",
    )  # fmt: skip
    paths = write_view(out, view)
    typer.echo(f"wrote {paths['image']}, {paths['meta']} and {paths['truth']}")


@app.command()
@input_errors
def estimate(
    meta: Annotated[Path, typer.Argument(help="meta.json (its 'image' is relative to it)")],
    image: Annotated[Path | None, typer.Option(help="the image, instead of meta.json's 'image'")] = None,
    method: Annotated[Literal["ours", "paper"], typer.Option(help="ours, or the paper's pipeline as written")] = "ours",
    require_axis: Annotated[bool, typer.Option(help="refuse weak perspective without a prior")] = False,
    seed: Annotated[int, typer.Option(min=0)] = 0,
    as_json: Annotated[bool, typer.Option("--json", help="print only the result JSON")] = False,
    out: Annotated[Path | None, typer.Option(help="also write result.json here")] = None,
    report: Annotated[Path | None, typer.Option(help="write the HTML report here")] = None,
    truth: Annotated[Path | None, typer.Option(help="with --report: a simulation's truth.json")] = None,
) -> None:
    """Estimate the panel axis from meta.json and its image."""
    from ..panel_axis.options import EstimateOptions
    from ..panel_axis.pipeline import load_input, run, write_result

    truth_doc = None
    if truth is not None:  # read before the estimate, so a bad file is refused before any work
        from ..panel_axis.report import load_truth

        truth_doc = load_truth(truth.read_bytes())
    with json_stdout(as_json):  # OpenCV or Open3D chatter goes to stderr, not into the JSON
        data = load_input(meta, image)
        result = run(data, EstimateOptions(method=method, require_axis=require_axis, seed=seed))
        doc = result.to_json()
        if out is not None:
            write_result(out, result)
        if report is not None:
            from ..panel_axis.report import build_report

            report.write_text(build_report(data.gray, data.meta, doc, truth_doc))
    if as_json:
        typer.echo(json.dumps(doc))
        return
    axis = result.axis
    typer.echo(f"regime: {result.observability.regime} (perspective SNR {result.observability.perspective_snr})")
    typer.echo(f"in-image angle: {result.image_angle_deg:.3f} deg")
    if axis is None:
        typer.echo("axis: not observable (weak perspective without a panel-size prior)")
    else:
        typer.echo(f"axis (camera): {[round(x, 6) for x in axis.camera]}, sigma {axis.sigma_deg} deg")
        if axis.station_enu is not None:
            typer.echo(f"axis (station ENU): {[round(x, 6) for x in axis.station_enu]}")
            typer.echo(f"pitch {axis.pitch_deg:.3f} deg, yaw {axis.yaw_deg:.3f} deg")
    if result.ambiguous:
        typer.echo("ambiguous: the axis and its mirror twin fit equally well (weak perspective)")
    for w in result.warnings:
        typer.echo(f"warning: {w}")
