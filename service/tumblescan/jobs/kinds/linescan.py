"""The ``linescan-motion`` job kind: motion from feature tracks (plus an optional cloud with
per-point times, rectified), or from dense frames alone (PLY or NPZ), rectified in full.

Thin by design: validation and the work itself are ``tumblescan.linescan.pipeline``'s, shared
with the CLI; this adapter declares the kind and moves files."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from ...errors import LimitExceededError, MalformedInputError
from ...io.sniff import sniff
from ...linescan.options import FramesOptions, TracksOptions
from ...linescan.pipeline import input_form
from ...linescan.result import MotionResult
from ..kind import ArtifactSpec, FinishedJob, InputForm, InputPart, JobContext, JobOutput, Submission, form_named

TRACKS_FILE = "input-tracks.json"
CLOUD_FILE = "cloud.ply"


class LinescanLimits(BaseModel):
    """Input sizes a deployment accepts (``TUMBLESCAN_MAX_OBSERVATIONS``, ``TUMBLESCAN_MAX_CLOUD_POINTS``)."""

    model_config = ConfigDict(extra="forbid")

    max_observations: int = Field(1_000_000, gt=0, description="largest tracks input")
    max_cloud_points: int = Field(50_000_000, gt=0, description="largest cloud (frames or the cloud to rectify)")


TRUTH_PART = InputPart("truth", "truth.json of a simulation, shown beside the estimate in the report", ("json",), False)
TRACKS = InputForm(
    name="tracks",
    description="feature tracks (JSON or CSV), optionally with a cloud with per-point times to rectify",
    options=TracksOptions,
    parts=(
        InputPart("file", "feature tracks", ("json", "csv")),
        InputPart("cloud", "PLY with per-point times, rectified with the estimated motion", ("ply",), False),
        TRUTH_PART,
    ),
    json_input=True,
    json_schema={
        "type": "object",
        "properties": {"tracks": {"type": "object", "description": "tracks JSON (see the README)"}},
        "required": ["tracks"],
        "additionalProperties": False,
    },
)
FRAMES = InputForm(
    name="frames",
    description="dense line-scan frames: every return with its time (binary PLY or NPZ)",
    options=FramesOptions,
    parts=(InputPart("file", "dense frames", ("ply", "npz")), TRUTH_PART),
)


class LinescanMotion:
    name = "linescan-motion"
    title = "Spin and precession of a tumbling target from line-scan lidar"
    forms: tuple[InputForm, ...] = (TRACKS, FRAMES)
    result_model: type[BaseModel] = MotionResult
    artifacts: tuple[ArtifactSpec, ...] = (
        ArtifactSpec("cloud", "application/octet-stream", "the cloud rectified to the reference time (binary PLY)"),
    )
    limits_model: type[BaseModel] = LinescanLimits

    def form_of(self, files: Mapping[str, list[Path]], payload: Any) -> InputForm:
        if payload is not None:
            return TRACKS
        if "file" not in files:
            raise MalformedInputError(
                "an upload needs 'file' (tracks as JSON or CSV, or frames as PLY or NPZ)", field="file"
            )
        return form_named(self, input_form(files["file"][0]))

    def accept(self, sub: Submission) -> dict[str, str]:
        from ...linescan.frames import read_frames
        from ...linescan.tracks_io import read_tracks, tracks_from_json
        from ...linescan.truth import load_truth

        limits = sub.limits
        assert isinstance(limits, LinescanLimits)
        accepted: dict[str, str] = {}
        if sub.form is TRACKS:
            if sub.payload is not None:
                tracks = tracks_from_json(_tracks_payload(sub.payload))
                accepted["tracks"] = _relative(sub.save(TRACKS_FILE, json.dumps(sub.payload["tracks"]).encode()), sub)
            else:
                tracks = read_tracks(sub.files["file"][0])
                accepted["tracks"] = _relative(sub.files["file"][0], sub)
            _check(len(tracks), limits.max_observations, "observations")
            if "cloud" in sub.files:
                cloud = sub.files["cloud"][0]
                if sniff(cloud) != "ply":
                    raise MalformedInputError("'cloud' must be a PLY with per-point times", field="cloud")
                from ...io.ply import read_ply

                _check(len(read_ply(cloud)), limits.max_cloud_points, "cloud")
                accepted["cloud"] = _relative(cloud, sub)
        else:
            if "cloud" in sub.files:
                raise MalformedInputError(
                    "'cloud' goes with tracks; a frames file is itself the cloud that is rectified", field="cloud"
                )
            options = sub.options
            assert isinstance(options, FramesOptions)
            # Assembled in full now, so a cloud that cannot be split into frames is refused at once.
            path = sub.files["file"][0]
            frames = read_frames(path, frame_period_s=options.frame_period_s, max_bytes=limits.max_cloud_points * 64)
            _check(len(frames.cloud), limits.max_cloud_points, "file")
            accepted["frames"] = _relative(path, sub)
        if "truth" in sub.files:
            load_truth(sub.files["truth"][0])
            accepted["truth"] = _relative(sub.files["truth"][0], sub)
        return accepted

    def run(self, ctx: JobContext) -> JobOutput:
        from ...io.ply import write_ply
        from ...linescan.pipeline import estimate_frames, estimate_tracks

        if "frames" in ctx.inputs:
            outcome = estimate_frames(
                ctx.inputs["frames"], FramesOptions.model_validate(ctx.options), progress=ctx.progress
            )
        else:
            outcome = estimate_tracks(
                ctx.inputs["tracks"],
                TracksOptions.model_validate(ctx.options),
                cloud_path=ctx.inputs.get("cloud"),
                progress=ctx.progress,
            )
        artifacts: dict[str, str] = {}
        if outcome.rectified is not None:
            ctx.progress("writing", 0.96)
            write_ply(ctx.output_path(CLOUD_FILE), outcome.rectified)
            artifacts["cloud"] = CLOUD_FILE
        return JobOutput(result=outcome.result.model_dump(mode="json"), artifacts=artifacts)

    def report(self, job: FinishedJob) -> str:
        from ...io.ply import read_ply
        from ...linescan.frames import read_frames
        from ...linescan.report import ReportInputs, build_report
        from ...linescan.tracks_io import read_tracks
        from ...linescan.truth import load_truth

        # Truth beside the estimate when the input was simulated.
        frames = "frames" in job.inputs
        distorted = read_ply(job.inputs["cloud"]) if "cloud" in job.inputs else None
        if frames:
            period = FramesOptions.model_validate(job.options).frame_period_s
            distorted = read_frames(job.inputs["frames"], frame_period_s=period).cloud
        inputs = ReportInputs(
            result=MotionResult.model_validate(job.result),
            title=f"Job {job.id}",
            tracks=None if frames else read_tracks(job.inputs["tracks"]),
            distorted=distorted,
            rectified=read_ply(job.artifacts["cloud"]) if "cloud" in job.artifacts else None,
            truth=load_truth(job.inputs["truth"]) if "truth" in job.inputs else None,
        )
        return build_report(inputs)


def _tracks_payload(payload: Any) -> Any:
    if not isinstance(payload, dict) or set(payload) != {"tracks"}:
        keys = sorted(payload) if isinstance(payload, dict) else []
        raise MalformedInputError(f'input must be {{"tracks": ...}}; got keys {keys}', field="input")
    return payload["tracks"]


def _relative(path: Path, sub: Submission) -> str:
    return str(path.relative_to(sub.job_dir))


def _check(count: int, limit: int, field: str) -> None:
    if count > limit:
        what = f"{count} observations" if field == "observations" else f"{field} has {count} points"
        raise LimitExceededError(f"{what}; the limit is {limit}", field=field)
