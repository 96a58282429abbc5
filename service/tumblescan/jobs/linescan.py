"""The ``linescan-motion`` job kind: motion from feature tracks (plus an optional cloud with
per-point times, rectified), or from dense frames alone (PLY or NPZ), rectified in full."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pydantic import BaseModel

from ..cloud_io import TimedCloud, read_ply, write_ply
from ..errors import InputError, LimitExceededError, MalformedInputError
from ..estimate import EstimateOptions, estimate_motion
from ..estimate_frames import estimate_from_frames
from ..frames import read_frames
from ..linescan.report import ReportInputs, build_report
from ..motion import Motion
from ..rectify import rectify
from ..result import MotionResult
from ..tracks import Tracks
from ..tracks_io import read_tracks, tracks_from_json
from ..truth import motion_from_json
from .kinds import FinishedJob, JobContext, JobOutput, Limits, register

TRACKS_FILE = "input-tracks"
CLOUD_FILE = "input-cloud.ply"


class LinescanMotion:
    name = "linescan-motion"
    options_model: type[BaseModel] = EstimateOptions

    def accept_json(self, payload: Any, save: Callable[[str, bytes], Path], limits: Limits) -> dict[str, str]:
        if not isinstance(payload, dict) or set(payload) != {"tracks"}:
            keys = sorted(payload) if isinstance(payload, dict) else []
            raise MalformedInputError(f'input must be {{"tracks": ...}}; got keys {keys}', field="input")
        _check_tracks(tracks_from_json(payload["tracks"]), limits)  # validated in full before the job is accepted
        save(TRACKS_FILE + ".json", json.dumps(payload["tracks"]).encode())
        return {"tracks": TRACKS_FILE + ".json"}

    def accept_files(self, files: dict[str, Path], limits: Limits, options: dict[str, Any]) -> dict[str, str]:
        unknown = sorted(set(files) - {"file", "cloud", "truth"})
        if unknown:
            raise MalformedInputError(f"unknown upload field(s): {', '.join(unknown)}", field=unknown[0])
        if "file" not in files:
            raise MalformedInputError(
                "an upload needs 'file' (tracks as JSON or CSV, or frames as PLY or NPZ)", field="file"
            )
        accepted = (
            self._accept_frames(files, limits, options)
            if sniff(files["file"]) in ("ply", "npz")
            else self._accept_tracks(files, limits)
        )
        if "truth" in files:
            load_truth(files["truth"])
            accepted["truth"] = files["truth"].name
        return accepted

    def _accept_tracks(self, files: dict[str, Path], limits: Limits) -> dict[str, str]:
        _check_tracks(read_tracks(files["file"]), limits)
        accepted = {"tracks": files["file"].name}
        if "cloud" in files:
            if sniff(files["cloud"]) != "ply":
                raise MalformedInputError("'cloud' must be a PLY with per-point times", field="cloud")
            _check_points(len(read_ply(files["cloud"])), limits, "cloud")
            accepted["cloud"] = files["cloud"].name
        return accepted

    def _accept_frames(self, files: dict[str, Path], limits: Limits, options: dict[str, Any]) -> dict[str, str]:
        if "cloud" in files:
            raise MalformedInputError(
                "'cloud' goes with tracks; a frames file is itself the cloud that is rectified", field="cloud"
            )
        period = EstimateOptions.model_validate(options).frame_period_s
        # Assembled in full now, so a cloud that cannot be split into frames is refused at once.
        frames = read_frames(files["file"], frame_period_s=period, max_bytes=limits.max_cloud_points * 64)
        _check_points(len(frames.cloud), limits, "file")
        return {"frames": files["file"].name}

    def run(self, ctx: JobContext) -> JobOutput:
        options = EstimateOptions.model_validate(ctx.options)
        if "frames" in ctx.inputs:
            return self._run_frames(ctx, options)
        # 1. Read and validate the tracks.
        ctx.progress("loading", 0.02)
        tracks = read_tracks(ctx.inputs["tracks"])
        # 2. Estimate, reporting through the attempts (each report is a cancellation point).
        result = estimate_motion(tracks, options, progress=lambda stage, f: ctx.progress(stage, 0.05 + 0.75 * f))
        artifacts: dict[str, str] = {}
        # 3. Rectify the cloud, if one came with the tracks.
        if "cloud" in ctx.inputs:
            ctx.progress("rectifying", 0.85)
            artifacts["cloud"] = _rectified(ctx, read_ply(ctx.inputs["cloud"]), result)
        return JobOutput(result=result.model_dump(mode="json"), artifacts=artifacts)

    def _run_frames(self, ctx: JobContext, options: EstimateOptions) -> JobOutput:
        # 1. Split the cloud into frames and lines.
        ctx.progress("assembling", 0.01)
        frames = read_frames(ctx.inputs["frames"], frame_period_s=options.frame_period_s)
        # 2-4. Register, initialize and refine (stages reported by the estimator).
        result = estimate_from_frames(frames, options, progress=lambda stage, f: ctx.progress(stage, 0.03 + 0.85 * f))
        # 5. Rectify every point to the reference time.
        ctx.progress("rectifying", 0.9)
        return JobOutput(
            result=result.model_dump(mode="json"), artifacts={"cloud": _rectified(ctx, frames.cloud, result)}
        )

    def report(self, job: FinishedJob) -> str:
        # Truth beside the estimate when the input was simulated.
        frames = "frames" in job.inputs
        distorted = read_ply(job.inputs["cloud"]) if "cloud" in job.inputs else None
        if frames:
            distorted = read_frames(job.inputs["frames"], frame_period_s=job_period(job)).cloud
        inputs = ReportInputs(
            result=MotionResult.model_validate(job.result),
            title=f"Job {job.id}",
            tracks=None if frames else read_tracks(job.inputs["tracks"]),
            distorted=distorted,
            rectified=read_ply(job.artifacts["cloud"]) if "cloud" in job.artifacts else None,
            truth=load_truth(job.inputs["truth"]) if "truth" in job.inputs else None,
        )
        return build_report(inputs)


def job_period(job: FinishedJob) -> float | None:
    return EstimateOptions.model_validate(job.options).frame_period_s


def _rectified(ctx: JobContext, cloud: TimedCloud, result: MotionResult) -> str:
    """Write ``cloud`` rectified to the result's reference time, every original field kept."""
    xyz = rectify(cloud.xyz_m, cloud.t_s, result.motion(), to_time_s=result.reference_time_s)
    ctx.progress("writing", 0.95)
    write_ply(ctx.output_path("cloud.ply"), TimedCloud(xyz, cloud.t_s, cloud.fields))
    return "cloud.ply"


def _check_points(points: int, limits: Limits, field: str) -> None:
    if points > limits.max_cloud_points:
        raise LimitExceededError(f"{field} has {points} points; the limit is {limits.max_cloud_points}", field=field)


def _check_tracks(tracks: Tracks, limits: Limits) -> None:
    if len(tracks) > limits.max_observations:
        raise LimitExceededError(
            f"{len(tracks)} observations; the limit is {limits.max_observations}", field="observations"
        )


def load_truth(path: Path) -> Motion:
    """The ``motion`` of a ``truth.json`` written by ``tumblescan simulate``."""
    try:
        return motion_from_json(json.loads(path.read_text())["motion"])
    except (ValueError, KeyError, TypeError) as exc:
        raise MalformedInputError(
            f"'truth' is not a simulation truth file ({type(exc).__name__}: {exc})", field="truth"
        ) from None


def sniff(path: Path) -> str:
    """'ply', 'npz', 'json' or 'csv' from the first bytes (names are not trusted)."""
    with open(path, "rb") as fh:
        head = fh.read(64)
    if head.startswith(b"ply"):
        return "ply"
    if head.startswith(b"PK"):
        return "npz"
    if head.lstrip().startswith((b"{", b"[")):
        return "json"
    if head.lstrip().lower().startswith(b"track"):
        return "csv"
    raise MalformedInputError("file is neither tracks (JSON, CSV) nor a PLY or NPZ cloud", field="file")


__all__ = ["InputError", "LinescanMotion", "sniff"]

register(LinescanMotion())
