"""``tumblescan linescan-motion simulate | estimate | rectify`` (also at the top level).

``estimate`` runs the same pipeline as the job (``tumblescan.linescan.pipeline``)."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from ..errors import InputError
from ..linescan.choices import ModelChoice, Objective, ShapeName, Strategy
from .common import input_errors, json_stdout

if TYPE_CHECKING:
    from ..linescan.pipeline import Outcome
    from ..linescan.result import MotionResult
    from ..linescan.sensor import SensorNoise

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
    """Simulate a tumbling satellite: writes tracks.json, frames.ply and truth.json."""
    import numpy as np

    from ..io.ply import TimedCloud, write_ply
    from ..linescan.sensor import Scanner
    from ..linescan.simulate import Scene, random_motion, simulate_frames, simulate_tracks
    from ..linescan.tracks_io import write_tracks
    from ..linescan.truth import motion_to_json

    rng = np.random.default_rng(seed)
    ws = (spin_rate_deg_s, spin_rate_deg_s) if spin_rate_deg_s is not None else (15.0, 37.0)
    wp = (precession_rate_deg_s, precession_rate_deg_s) if precession_rate_deg_s is not None else (3.0, 14.0)
    motion = random_motion(rng, distance_m=distance_m, spin_rate_deg_s=ws, precession_rate_deg_s=wp)
    scene = Scene(
        scanner=Scanner(lines=lines, pixels=pixels), frames=frames, noise=noise, shape=_shape(shape, mesh, size_m)
    )
    out.mkdir(parents=True, exist_ok=True)
    tracks, track_truth = simulate_tracks(motion, scene, seed=seed)
    write_tracks(out / "tracks.json", tracks)
    truth = {"motion": motion_to_json(motion), "scene": scene.model_dump(mode="json"), "seed": seed}
    truth["corners_reference_m"] = track_truth.corners_reference_m.tolist()
    typer.echo(
        f"wrote {out / 'tracks.json'} ({len(tracks)} observations of {tracks.n_tracks} corners "
        f"in {tracks.n_frames} frames)"
    )
    if dense:
        cloud = simulate_frames(motion, scene, seed=seed)
        fields: dict[str, np.ndarray] = {"frame": cloud.frame, "line": cloud.line, "pixel": cloud.pixel}
        write_ply(out / "frames.ply", TimedCloud(cloud.xyz_m, cloud.t_s, fields))
        write_ply(
            out / "reference.ply",
            TimedCloud(cloud.reference_m, np.full(len(cloud.t_s), motion.reference_time_s), dict(fields)),
        )
        typer.echo(f"wrote {out / 'frames.ply'} ({len(cloud.t_s)} points) and the undistorted {out / 'reference.ply'}")
    (out / "truth.json").write_text(json.dumps(truth, indent=2))
    typer.echo(f"wrote {out / 'truth.json'}")


@app.command()
@input_errors
def estimate(
    tracks_file: Annotated[Path, typer.Argument(help="tracks (JSON, CSV) or dense frames (PLY, NPZ)")],
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
        float | None, typer.Option(min=0.0, help="frames input without frame indices: the scanner's frame period")
    ] = None,
) -> None:
    """Estimate the motion from feature tracks or dense frames and print it; frames (and a
    cloud given with tracks) are also rectified to the reference time."""
    from ..linescan.options import FramesOptions, TracksOptions
    from ..linescan.pipeline import estimate_frames, estimate_tracks, input_form

    form = input_form(tracks_file)
    common: dict[str, Any] = {"model": model, "reference_time_s": reference_time_s, "seed": seed}
    if form == "frames":
        _refuse_for_frames(strategy=strategy, objective=objective, cloud=cloud)
        sensor = _sensor(None, range_sigma_m, angle_sigma_arcsec)
        frames_options = FramesOptions(**common, sensor=sensor, frame_period_s=frame_period_s)
        with json_stdout(as_json):
            outcome = estimate_frames(tracks_file, frames_options)
        out: Path | None = rectified or tracks_file.with_name(tracks_file.stem + "-rectified.ply")
    else:
        if frame_period_s is not None:
            raise InputError("--frame-period-s applies to frames input, not to tracks", field="frame_period_s")
        declared = _declared_noise(tracks_file) if range_sigma_m is not None or angle_sigma_arcsec is not None else None
        tracks_options = TracksOptions(
            **common,
            strategy=strategy or "auto",
            objective=objective or "ml",
            sensor=_sensor(declared, range_sigma_m, angle_sigma_arcsec),
        )
        with json_stdout(as_json):
            outcome = estimate_tracks(tracks_file, tracks_options, cloud_path=cloud)
        out = rectified or (cloud.with_name(cloud.stem + "-rectified.ply") if cloud is not None else None)
    _write_outputs(outcome, tracks_file, out, report, truth)
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
    if not mesh.is_file():
        raise InputError(f"no such mesh file: {mesh}", field="mesh")
    return MeshFileShape(path=str(mesh.resolve()), size_m=size_m)


def _refuse_for_frames(**given: object) -> None:
    """Options of tracks input given with frames: refused by name, never ignored."""
    for name, value in given.items():
        if value is not None:
            raise InputError(f"--{name} applies to tracks input, not to frames", field=name)


def _declared_noise(path: Path) -> SensorNoise | None:
    from ..linescan.tracks_io import read_tracks

    return read_tracks(path).sensor


def _write_outputs(outcome: Outcome, source: Path, out: Path | None, report: Path | None, truth: Path | None) -> None:
    """The rectified cloud and the report, as the job writes them."""
    from ..io.ply import write_ply

    rectified = outcome.rectified
    if out is not None and rectified is not None:
        write_ply(out, rectified)
        typer.echo(f"wrote {out}: {len(rectified)} points rectified to t={outcome.result.reference_time_s} s", err=True)
    if report is None:
        return
    from ..linescan.report import ReportInputs, build_report
    from ..linescan.truth import load_truth

    inputs = ReportInputs(
        result=outcome.result,
        title=f"Motion estimate: {source.stem}",
        tracks=outcome.tracks,
        distorted=outcome.cloud,
        rectified=rectified,
        truth=load_truth(truth) if truth is not None else None,
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
    from ..linescan.rectify import rectify as rectify_points

    result = load_result(motion)
    cloud = read_ply(cloud_file)
    target = float(cloud.t_s.min()) if reference_time_s is None and len(cloud) else (reference_time_s or 0.0)
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
        _fit_line(r),
        f"validation       {'passed' if r.validation.passed else 'FAILED'} "
        f"({r.validation.test}, frames {r.validation.frames})",
        f"solver           {r.solver.path}, {r.solver.iterations} evaluations, {r.solver.attempts} attempt(s), "
        f"{r.solver.elapsed_s * 1000:.0f} ms",
    ]
    lines += [f"warning          {w}" for w in r.warnings]
    return "\n".join(lines)


def _fit_line(r: MotionResult) -> str:
    f = r.fit
    if f.source == "frames":
        worst = max(((v, i) for i, v in enumerate(f.frame_rms_m or []) if v is not None), default=None)
        tail = f", worst frame {worst[1]} ({worst[0]:.3g} m)" if worst else ""
        return (
            f"fit              rms {f.rms_residual_m:.3g} m surfel-to-plane, {f.points_used} of "
            f"{f.observations} points, {f.frames} frames{tail}"
        )
    return (
        f"fit              rms {f.rms_residual_m:.3g} m over {f.observations} observations, "
        f"{f.tracks} tracks, {f.frames} frames, {f.outliers} outliers"
    )


def _vec(v: Any, digits: int = 6) -> str:
    return "[" + ", ".join(f"{x:.{digits}f}" for x in v) + "]"


def main() -> None:
    app()
