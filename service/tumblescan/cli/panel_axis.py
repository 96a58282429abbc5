"""``tumblescan panel-axis simulate | estimate``: the solar-panel axis from one optical image."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal

import typer

from ..errors import InputError
from .common import check_output_files, input_errors, json_stdout, options_from_flags

if TYPE_CHECKING:
    pass

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
    require_axis: Annotated[
        bool, typer.Option(help="refuse weak perspective without a prior (method ours: the paper's cannot tell it)")
    ] = False,
    seed: Annotated[int, typer.Option(min=0)] = 0,
    as_json: Annotated[bool, typer.Option("--json", help="print only the result JSON")] = False,
    out: Annotated[Path | None, typer.Option(help="also write result.json here")] = None,
    report: Annotated[Path | None, typer.Option(help="write the HTML report here")] = None,
    truth: Annotated[Path | None, typer.Option(help="with --report: a simulation's truth.json")] = None,
) -> None:
    """Estimate the panel axis from meta.json and its image."""
    # Everything that can be refused is refused before the work, so nothing is half-written:
    # the options, where the outputs go, and the truth file.
    from ..panel_axis.options import EstimateOptions
    from ..panel_axis.pipeline import load_input, run, write_result
    from ..panel_axis.summary import summary_lines

    options = options_from_flags(EstimateOptions, {"method": method, "require_axis": require_axis, "seed": seed})
    if truth is not None and report is None:  # the truth is only ever drawn into the report
        raise InputError("--truth goes with --report (the truth is shown in the HTML report only)", field="truth")
    check_output_files(out=out, report=report)
    truth_doc = None
    if truth is not None:
        from ..panel_axis.report import load_truth

        truth_doc = load_truth(truth.read_bytes())
    with json_stdout(as_json):  # OpenCV or Open3D chatter goes to stderr, not into the JSON
        data = load_input(meta, image)
        result = run(data, options)
        doc = result.to_json()
        page = None
        if report is not None:  # built before either file is written: a failure here writes nothing
            from ..panel_axis.report import build_report

            page = build_report(data.gray, data.meta, doc, truth_doc)
        if out is not None:
            write_result(out, result)
        if report is not None and page is not None:  # (page is set whenever report is)
            report.write_text(page)
    if as_json:
        typer.echo(json.dumps(doc))
        return
    for line in summary_lines(result):
        typer.echo(line)
