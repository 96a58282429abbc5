"""``tumblescan spin-from-images simulate | estimate``: spin rate and axis from an image sequence."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import Annotated, Literal

import typer

from .common import input_errors, json_stdout

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="spin-from-images: spin rate and axis from a monocular image sequence.",
)


@app.command()
@input_errors
def simulate(
    out: Annotated[Path, typer.Option(help="output directory")] = Path("spin-sim"),
    seed: Annotated[int, typer.Option(min=0)] = 0,
    kind: Annotated[
        Literal["oblique", "los", "plane", "static", "aliased", "blank", "corrupt", "broken-meta"],
        typer.Option(help="axis geometry, or a refusal case"),
    ] = "oblique",
    noise: Annotated[bool, typer.Option(help="shot and read noise, stars")] = False,
    width_px: Annotated[int, typer.Option(min=64, max=4096)] = 512,
    frames: Annotated[int, typer.Option(min=6, max=200)] = 16,
    bits: Annotated[int, typer.Option(help="8 or 16")] = 8,
    tiff: Annotated[bool, typer.Option(help="TIFF frames instead of PNG")] = False,
    drift: Annotated[bool, typer.Option(help="a slow drift of the centre (0.3-1.5 px per frame)")] = False,
    broken: Annotated[str | None, typer.Option(help="with --kind broken-meta: which field to break")] = None,
) -> None:
    """Render a flat-spinning satellite: frames/, meta.json and truth.json."""
    from ..spin_rate.simulate import BROKEN_META, simulate_sequence, write_sequence

    if bits not in (8, 16):
        raise typer.BadParameter("--bits must be 8 or 16")
    if broken is not None and broken not in BROKEN_META:
        raise typer.BadParameter(f"--broken must be one of {', '.join(BROKEN_META)}")
    seq = simulate_sequence(seed, kind, noises=(noise,), width_px=width_px, frames=frames, bits=bits, tiff=tiff,
                            drift=drift, broken=broken)  # fmt: skip
    meta = write_sequence(out, seq)
    typer.echo(f"wrote {meta}, {out / 'truth.json'} and {len(seq.images[0])} frames in {out / 'frames'}")


@app.command()
@input_errors
def estimate(
    source: Annotated[Path, typer.Argument(help="a directory with meta.json, a meta.json, or a zip of them")],
    method: Annotated[Literal["ours", "paper"], typer.Option(help="ours, or the paper's mean-point sine fit")] = "ours",
    as_json: Annotated[bool, typer.Option("--json", help="print only the result JSON")] = False,
    out: Annotated[Path | None, typer.Option(help="also write result.json here")] = None,
    report: Annotated[Path | None, typer.Option(help="write the HTML report here")] = None,
    tracks: Annotated[bool, typer.Option(help="add per-track observations")] = False,
) -> None:
    """Estimate the spin rate (and axis, sense) from meta.json and its frames."""
    from ..spin_rate.options import EstimateOptions
    from ..spin_rate.pipeline import load_input, resolve_input, run, write_result

    with tempfile.TemporaryDirectory() as tmp, json_stdout(as_json):
        meta = resolve_input(source, Path(tmp))
        seq = load_input(meta)
        result = run(seq, EstimateOptions(method=method, return_tracks=tracks or (report is not None) or None))
        doc = result.to_json()
        if out is not None:
            write_result(out, result)
        if report is not None:
            from ..spin_rate.report import build_report

            report.write_text(build_report(seq, doc))
    if as_json:
        typer.echo(json.dumps(doc))
        return
    s = result.spin
    if not s.spinning:
        typer.echo(f"not spinning (rate under {s.sigma_rate_deg_s} deg/s)")
    else:
        typer.echo(f"rate: {s.rate_deg_s:.4f} ± {s.sigma_rate_deg_s:.4f} deg/s (period {s.period_s} s)")
        typer.echo(f"axis (camera): {s.axis_camera}, {s.axis_los_angle_deg} deg from the line of sight")
        typer.echo(f"sense about the line of sight: {s.sense_about_los}")
        if s.axis_ambiguous:
            typer.echo(f"ambiguous: the mirror twin {s.axis_candidates[0].axis_camera} fits as well")
    typer.echo(f"tracks {result.quality.line_tracks}, rms {result.quality.fit_rms_px} px, flags {result.quality.flags}")
