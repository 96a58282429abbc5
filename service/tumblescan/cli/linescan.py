"""``tumblescan linescan-motion simulate | estimate | rectify`` (also at the top level).

``estimate`` runs the same pipeline as the job (``tumblescan.linescan.pipeline``)."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from ..errors import InputError
from ..linescan.choices import ModelChoice, Objective, ShapeName, Strategy
from .common import check_output_files, input_errors, json_stdout

if TYPE_CHECKING:
    from ..linescan.pipeline import Outcome
    from ..linescan.result import MotionResult
    from ..linescan.sensor import SensorNoise
    from ..target.motion import Motion

app = typer.Typer(
    add_completion=False, no_args_is_help=True, help="linescan-motion: spin and precession from line-scan lidar."
)


@app.command()
@input_errors
def simulate(
    out: Annotated[Path, typer.Option(help="output directory")] = Path("sim"),
    distance_m: Annotated[
        float, typer.Option("--distance-m", "--range-m", min=1.0, help="range to the precession centre")
    ] = 50.0,
    shape: Annotated[
        ShapeName, typer.Option(help="target: the box satellite or a shape of the library (docs/linescan.md)")
    ] = "box",
    mesh: Annotated[Path | None, typer.Option(help="target from a mesh file Open3D reads (GLB, OBJ, PLY, STL)")] = None,
    size_m: Annotated[float | None, typer.Option(min=0.01, help="with --mesh: its largest side, metres")] = None,
    frames: Annotated[int, typer.Option(min=4, max=200)] = 15,
    seed: Annotated[int, typer.Option(min=0)] = 0,
    spin_rate_deg_s: Annotated[float | None, typer.Option(help="default: random in 15-37")] = None,
    precession_rate_deg_s: Annotated[float | None, typer.Option(help="default: random in 3-14")] = None,
    noise: Annotated[bool, typer.Option(help="add Table 1 sensor noise")] = True,
    lines: Annotated[int, typer.Option(min=2, max=8192)] = 512,
    pixels: Annotated[int, typer.Option(min=1, max=8192)] = 512,
    dense: Annotated[bool, typer.Option(help="also cast every ray into frames.ply")] = True,
) -> None:
    """Simulate a tumbling satellite: writes tracks.json, frames.ply, reference.ply (the frames'
    points without the motion's smear) and truth.json."""
    import numpy as np

    from ..io.ply import TimedCloud, write_ply
    from ..linescan.errors import SingleObservationTrackError, TooFewTracksError
    from ..linescan.sensor import Scanner
    from ..linescan.simulate import Scene, random_motion, simulate_frames, simulate_tracks
    from ..linescan.tracks_io import write_tracks
    from ..linescan.truth import motion_to_json

    _finite(distance_m=distance_m, size_m=size_m, spin_rate_deg_s=spin_rate_deg_s,
            precession_rate_deg_s=precession_rate_deg_s)  # fmt: skip
    scanner = Scanner(lines=lines, pixels=pixels)
    if distance_m > scanner.max_range_m:
        raise InputError(
            f"--range-m: {distance_m:g} m is beyond the scanner's maximum range ({scanner.max_range_m:g} m)",
            field="distance_m",
        )
    rng = np.random.default_rng(seed)
    ws = (spin_rate_deg_s, spin_rate_deg_s) if spin_rate_deg_s is not None else (15.0, 37.0)
    wp = (precession_rate_deg_s, precession_rate_deg_s) if precession_rate_deg_s is not None else (3.0, 14.0)
    motion = random_motion(rng, distance_m=distance_m, spin_rate_deg_s=ws, precession_rate_deg_s=wp)
    scene = Scene(scanner=scanner, frames=frames, noise=noise, shape=_shape(shape, mesh, size_m))
    # Everything is simulated before anything is written: a target out of view leaves no files.
    try:
        tracks, track_truth = simulate_tracks(motion, scene, seed=seed)
    except (TooFewTracksError, SingleObservationTrackError):
        raise InputError(_out_of_view(distance_m, "too few of the target's corners"), field="distance_m") from None
    cloud = simulate_frames(motion, scene, seed=seed) if dense else None
    if cloud is not None and len(cloud.t_s) == 0:
        raise InputError(_out_of_view(distance_m, "no part of the target"), field="distance_m")
    _output_directory(out)
    write_tracks(out / "tracks.json", tracks)
    truth = {"motion": motion_to_json(motion), "scene": scene.model_dump(mode="json"), "seed": seed}
    truth["corners_reference_m"] = track_truth.corners_reference_m.tolist()
    typer.echo(
        f"wrote {out / 'tracks.json'} ({len(tracks)} observations of {tracks.n_tracks} corners "
        f"in {tracks.n_frames} frames)"
    )
    if cloud is not None:
        fields: dict[str, np.ndarray] = {"frame": cloud.frame, "line": cloud.line, "pixel": cloud.pixel}
        write_ply(out / "frames.ply", TimedCloud(cloud.xyz_m, cloud.t_s, fields))
        write_ply(
            out / "reference.ply",
            TimedCloud(cloud.reference_m, np.full(len(cloud.t_s), motion.reference_time_s), dict(fields)),
        )
        typer.echo(f"wrote {out / 'frames.ply'} ({len(cloud.t_s)} points) and the undistorted {out / 'reference.ply'}")
    (out / "truth.json").write_text(json.dumps(truth, indent=2))
    typer.echo(f"wrote {out / 'truth.json'}")


def _finite(**values: float | None) -> None:
    """Options given as NaN or infinity (typer's bounds let them through): refused by name."""
    for name, value in values.items():
        if value is not None and not math.isfinite(value):
            option = "range-m" if name == "distance_m" else name.replace("_", "-")
            raise InputError(f"--{option} must be a finite number, not {value}", field=name)


def _out_of_view(distance_m: float, what: str) -> str:
    return (
        f"the scanner sees {what} at {distance_m:g} m: check --size-m and --range-m (the target "
        "must lie in front of the scanner and fill part of its field of view)"
    )


def _output_directory(out: Path) -> None:
    """``--out`` made if missing; a file or an unwritable place refused by name."""
    if out.exists() and not out.is_dir():
        raise InputError(f"--out: {out} is a file, not a directory", field="out")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"--out: cannot make the directory {out} ({exc.strerror or exc})", field="out") from None


@app.command()
@input_errors
def estimate(
    input_file: Annotated[Path, typer.Argument(help="tracks (JSON, CSV) or dense frames (PLY, NPZ)")],
    strategy: Annotated[Strategy | None, typer.Option(help="tracks: auto, lm or swarm (default auto)")] = None,
    objective: Annotated[Objective | None, typer.Option(help="tracks: ml or pairwise (default ml)")] = None,
    model: Annotated[ModelChoice, typer.Option()] = "auto",
    reference_time_s: Annotated[float | None, typer.Option(help="default: first observation")] = None,
    seed: Annotated[int, typer.Option(min=0)] = 0,
    range_sigma_m: Annotated[float | None, typer.Option(help="override the declared range noise")] = None,
    angle_sigma_arcsec: Annotated[float | None, typer.Option(help="override the declared angle noise")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="print only the result JSON")] = False,
    report: Annotated[Path | None, typer.Option(help="write the HTML report here")] = None,
    cloud: Annotated[Path | None, typer.Option(help="tracks: a PLY with per-point times to rectify")] = None,
    truth: Annotated[
        Path | None, typer.Option(help="with --report: truth.json of a simulation, shown beside the estimate")
    ] = None,
    rectified: Annotated[
        Path | None,
        typer.Option(
            help="where the rectified cloud goes (frames default: <input>-rectified.ply; tracks: with --cloud)"
        ),
    ] = None,
    frame_period_s: Annotated[
        float | None, typer.Option(help="frames input without frame indices: the scanner's frame period (> 0)")
    ] = None,
) -> None:
    """Estimate the motion from feature tracks or dense frames and print it; frames (and a
    cloud given with tracks) are also rectified to the reference time."""
    from ..linescan.options import FramesOptions, TracksOptions
    from ..linescan.pipeline import estimate_frames, estimate_tracks, input_form
    from ..linescan.truth import load_truth

    # Options that would do nothing, and outputs with nowhere to go, are refused before the work.
    if truth is not None and report is None:
        raise InputError("--truth goes with --report (the report shows the truth beside the estimate)", field="truth")
    check_output_files(report=report, rectified=rectified)
    truth_motion = load_truth(truth) if truth is not None else None
    form = input_form(input_file)
    common: dict[str, Any] = {"model": model, "reference_time_s": reference_time_s, "seed": seed}
    if form == "frames":
        _refuse_for_frames(strategy=strategy, objective=objective, cloud=cloud)
        sensor = _sensor(None, range_sigma_m, angle_sigma_arcsec)
        frames_options = FramesOptions(**common, sensor=sensor, frame_period_s=frame_period_s)
        with json_stdout(as_json):
            outcome = estimate_frames(input_file, frames_options)
        out: Path | None = rectified or input_file.with_name(input_file.stem + "-rectified.ply")
    else:
        if frame_period_s is not None:
            raise InputError("--frame-period-s applies to frames input, not to tracks", field="frame_period_s")
        if rectified is not None and cloud is None:
            raise InputError("--rectified goes with --cloud for tracks input (the cloud to rectify)", field="rectified")
        declared = _declared_noise(input_file) if range_sigma_m is not None or angle_sigma_arcsec is not None else None
        tracks_options = TracksOptions(
            **common,
            strategy=strategy or "auto",
            objective=objective or "ml",
            sensor=_sensor(declared, range_sigma_m, angle_sigma_arcsec),
        )
        with json_stdout(as_json):
            outcome = estimate_tracks(input_file, tracks_options, cloud_path=cloud)
        out = rectified or (cloud.with_name(cloud.stem + "-rectified.ply") if cloud is not None else None)
    _write_outputs(outcome, input_file, out, report, truth_motion)
    _print_result(outcome.result, as_json=as_json)


def _shape(name: str, mesh: Path | None, size_m: float | None) -> Any:
    """The simulated target: ``--mesh`` (with ``--size-m``) or a named shape."""
    from ..target.shapes import PARAMETRIC, MeshFileShape, SatelliteShape

    if mesh is None:
        if size_m is not None:
            raise InputError("--size-m goes with --mesh", field="size_m")
        return PARAMETRIC[name]() if name in PARAMETRIC else SatelliteShape()
    if name != "box":
        raise InputError("give --shape or --mesh, not both", field="mesh")
    if size_m is None:
        raise InputError("--mesh needs --size-m (its largest side in metres)", field="size_m")
    if mesh.is_dir():
        raise InputError(f"--mesh: {mesh} is a directory, not a mesh file", field="mesh")
    if not mesh.is_file():
        raise InputError(f"--mesh: no such file: {mesh}", field="mesh")
    return MeshFileShape(path=str(mesh.resolve()), size_m=size_m)


def _refuse_for_frames(**given: object) -> None:
    """Options of tracks input given with frames: refused by name, never ignored."""
    for name, value in given.items():
        if value is not None:
            raise InputError(f"--{name} applies to tracks input, not to frames", field=name)


def _declared_noise(path: Path) -> SensorNoise | None:
    from ..linescan.tracks_io import read_tracks

    return read_tracks(path).sensor


def _write_outputs(outcome: Outcome, source: Path, out: Path | None, report: Path | None, truth: Motion | None) -> None:
    """The rectified cloud and the report, as the job writes them."""
    from ..io.ply import write_ply

    rectified = outcome.rectified
    if out is not None and rectified is not None:
        write_ply(out, rectified)
        typer.echo(f"wrote {out}: {len(rectified)} points rectified to t={outcome.result.reference_time_s} s", err=True)
    if report is None:
        return
    from ..linescan.report import ReportInputs, build_report

    inputs = ReportInputs(
        result=outcome.result,
        title=f"Motion estimate: {source.stem}",
        tracks=outcome.tracks,
        distorted=outcome.cloud,
        rectified=rectified,
        truth=truth,
    )
    report.write_text(build_report(inputs), encoding="utf-8")
    typer.echo(f"wrote {report}", err=True)


def _print_result(result: MotionResult, *, as_json: bool) -> None:
    if as_json:
        sys.stdout.write(result.model_dump_json() + "\n")
        sys.stdout.flush()
    else:
        typer.echo(format_result(result))


def _sensor(
    declared: SensorNoise | None, range_sigma_m: float | None, angle_sigma_arcsec: float | None
) -> SensorNoise | None:
    """The declared noise (default: Table 1's) with the command line's overrides, or None without any."""
    from ..linescan.sensor import SensorNoise

    if range_sigma_m is None and angle_sigma_arcsec is None:
        return None
    base = declared or SensorNoise()
    return SensorNoise(
        range_sigma_m=range_sigma_m if range_sigma_m is not None else base.range_sigma_m,
        angle_sigma_arcsec=angle_sigma_arcsec if angle_sigma_arcsec is not None else base.angle_sigma_arcsec,
    )


@app.command()
@input_errors
def rectify(
    cloud_file: Annotated[Path, typer.Argument(help="PLY with per-point times")],
    motion: Annotated[Path, typer.Option(help="result JSON from 'estimate --json'")],
    out: Annotated[Path, typer.Option(help="output PLY")],
    reference_time_s: Annotated[float | None, typer.Option(help="default: the cloud's earliest time")] = None,
) -> None:
    """Map every point of a cloud to one reference time with an estimated motion."""
    from ..io.ply import TimedCloud, read_ply, write_ply
    from ..linescan.options import check_reference_time
    from ..linescan.rectify import rectify as rectify_points

    _finite(reference_time_s=reference_time_s)
    check_output_files(out=out)
    result = load_result(motion)
    cloud = read_ply(cloud_file)
    t_first, t_last = (float(cloud.t_s.min()), float(cloud.t_s.max())) if len(cloud) else (0.0, 0.0)
    target = t_first if reference_time_s is None else reference_time_s
    # The rule of an estimate's reference time: a far one turns the motion's phase into noise.
    check_reference_time(target, t_first, t_last, named="--reference-time-s:", whose="the cloud's times",
                         field="reference_time_s")  # fmt: skip
    xyz = rectify_points(cloud.xyz_m, cloud.t_s, result.motion(), to_time_s=target)
    write_ply(out, TimedCloud(xyz, cloud.t_s, cloud.fields))
    typer.echo(f"wrote {out}: {len(cloud)} points rectified to t={target} s")


def load_result(path: Path) -> MotionResult:
    from pydantic import ValidationError

    from ..linescan.result import MotionResult

    try:
        return MotionResult.model_validate_json(path.read_text())
    except ValidationError as exc:
        err = exc.errors()[0]
        raise InputError(
            f"{path}: not a motion result ({'.'.join(map(str, err['loc']))}: {err['msg']})", field="motion"
        ) from None


def format_result(r: MotionResult) -> str:
    """A short human-readable summary with 1-sigma values."""
    from ..linescan.report_text import fit_text
    from ..report.html import sigmas_text

    u = r.uncertainty
    lines = [
        f"model            {r.model}   (reference time {r.reference_time_s:.6g} s)",
        f"spin axis        {_vec(r.spin.axis)}  +- {u.spin_axis_deg:.3g} deg",
        f"spin rate        {r.spin.rate_deg_s:.6f} +- {u.spin_rate_deg_s:.3g} deg/s",
    ]
    if r.precession.axis is not None:
        lines += [
            f"precession axis  {_vec(r.precession.axis)}  +- {u.precession_axis_deg:.3g} deg",
            f"precession rate  {r.precession.rate_deg_s:.6f} +- {u.precession_rate_deg_s:.3g} deg/s",
            f"nutation angle   {r.nutation_angle_deg:.4f} deg",
        ]
    lines += [
        f"centre           {_vec(r.precession.center_m)} m  +- {sigmas_text(u.center_m, 1000)} mm",
        f"fit              {fit_text(r.fit)}",
        f"validation       {'passed' if r.validation.passed else 'FAILED'} "
        f"({r.validation.test}, frames {r.validation.frames})",
        f"solver           {r.solver.path}, {r.solver.iterations} evaluations, {r.solver.attempts} attempt(s), "
        f"{r.solver.elapsed_s * 1000:.0f} ms",
    ]
    lines += [f"warning          {w}" for w in r.warnings]
    return "\n".join(lines)


def _vec(v: Any, digits: int = 6) -> str:
    return "[" + ", ".join(f"{x:.{digits}f}" for x in v) + "]"


def main() -> None:
    app()
