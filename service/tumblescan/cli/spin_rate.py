"""``tumblescan spin-from-images simulate | estimate``: spin rate and axis from an image sequence."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import Annotated, Literal

import typer

from ..errors import InputError
from .common import check_output_files, input_errors, json_stdout

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
        raise InputError(f"--bits must be 8 or 16, not {bits}", field="bits")
    if broken is not None and broken not in BROKEN_META:
        raise InputError(f"--broken must be one of {', '.join(BROKEN_META)}", field="broken")
    if broken is not None and kind != "broken-meta":  # it once wrote a valid sequence, ignoring --broken
        raise InputError(f"--broken goes with --kind broken-meta (not --kind {kind})", field="broken")
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
    tracks: Annotated[
        bool | None, typer.Option("--tracks/--no-tracks", help="add per-track observations (default: meta.json's)")
    ] = None,
) -> None:
    """Estimate the spin rate (and axis, sense) from meta.json and its frames."""
    from ..spin_rate.options import EstimateOptions
    from ..spin_rate.pipeline import load_input, resolve_input, run, write_result
    from ..spin_rate.text import summary_rows

    # Before the work (3-40 s): an output that cannot be written is refused with nothing written.
    check_output_files(out=out, report=report)
    options = EstimateOptions(method=method, return_tracks=tracks)
    with tempfile.TemporaryDirectory() as tmp, json_stdout(as_json):
        meta = resolve_input(source, Path(tmp))
        seq = load_input(meta)
        wanted = seq.meta.options.return_tracks if tracks is None else tracks
        # The report draws the tracked lines, so it needs the tracks; the result (stdout, --out)
        # carries them only when asked, whether or not there is a report.
        full = run(seq, options.model_copy(update={"return_tracks": True}) if report is not None else options)
        result = full if wanted else full.model_copy(update={"tracks": None})
        doc = result.to_json()
        if report is not None:
            from ..spin_rate.report import build_report

            html = build_report(seq, full.to_json())  # built before anything is written
        if out is not None:
            write_result(out, result)
        if report is not None:
            report.write_text(html)
    if as_json:
        typer.echo(json.dumps(doc))
        return
    for label, value in summary_rows(doc):
        typer.echo(f"{label}: {value}")
