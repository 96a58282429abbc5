"""The ``spin-from-images`` job kind: spin rate and axis from a monocular image sequence (upload
parts ``meta`` + ``frames``, or one ``archive`` zip). Thin: the work is ``spin_rate.pipeline``'s."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from ...errors import InputError, LimitExceededError
from ...spin_rate.options import EstimateOptions
from ...spin_rate.result import SpinResult
from ..kind import ArtifactSpec, FinishedJob, InputForm, InputPart, JobContext, JobOutput, Submission

STRIP_FILE = "strip.png"


class SpinLimits(BaseModel):
    """Input sizes a deployment accepts."""

    model_config = ConfigDict(extra="forbid")

    max_frames: int = Field(400, gt=0, description="most frames in one sequence")
    max_pixels: int = Field(16_000_000, gt=0, description="largest frame (pixels)")
    max_archive_bytes: int = Field(1_000_000_000, gt=0, description="largest zip upload")


FRAMES_FORM = InputForm(
    name="frames",
    description="meta.json (schema tumblescan.spin_from_images.input/1) and the PNG/TIFF frames it names",
    options=EstimateOptions,
    parts=(
        InputPart("meta", "meta.json: frames with mid-exposure times, camera, prior", ("json",)),
        InputPart(
            "frames", "the frames (8/16-bit PNG or TIFF), matched to meta.json by file name", ("png", "tiff"), many=True
        ),
    ),
)
ARCHIVE_FORM = InputForm(
    name="archive",
    description="one zip holding meta.json and the frames it names",
    options=EstimateOptions,
    parts=(InputPart("archive", "a zip of meta.json and its frames", ("zip",)),),
)


class SpinFromImages:
    name = "spin-from-images"
    title = "Spin rate and axis of a single-axis spinner from a monocular image sequence"
    forms: tuple[InputForm, ...] = (FRAMES_FORM, ARCHIVE_FORM)
    result_model: type[BaseModel] = SpinResult
    artifacts: tuple[ArtifactSpec, ...] = (
        ArtifactSpec("strip", "image/png", "a strip of frames with the tracked lines drawn"),
    )
    limits_model: type[BaseModel] = SpinLimits

    def form_of(self, files: Mapping[str, list[Path]], payload: Any) -> InputForm:
        if "archive" in files:
            return ARCHIVE_FORM
        for part in ("meta", "frames"):
            if part not in files:
                raise InputError(f"an upload needs '{part}' (or one 'archive' zip)", field=part)
        return FRAMES_FORM

    def accept(self, sub: Submission) -> dict[str, str]:
        from ...spin_rate.pipeline import load_input, unpack_zip

        limits = sub.limits
        assert isinstance(limits, SpinLimits)
        if sub.form.name == "archive":
            archive = sub.files["archive"][0]
            if archive.stat().st_size > limits.max_archive_bytes:
                raise LimitExceededError(f"archive: {archive.stat().st_size} bytes is over the limit", field="archive")
            meta = unpack_zip(archive, sub.job_dir / "unpacked")
            seq = load_input(meta)
        else:
            meta = sub.files["meta"][0]
            frames = {p.name: p for p in sub.files["frames"]}
            seq = load_input(meta, frames)  # every invalid_input / unreadable_image is a 422 now
            (sub.job_dir / "unpacked").mkdir(exist_ok=True)
        if len(seq.grays) > limits.max_frames:
            raise LimitExceededError(f"frames: {len(seq.grays)} frames (limit {limits.max_frames})", field="frames")
        if seq.grays[0].size > limits.max_pixels:
            raise LimitExceededError(
                f"frames: {seq.grays[0].size} px per frame (limit {limits.max_pixels})", field="frames"
            )
        out = {"meta": _relative(meta, sub)}
        if sub.form.name == "frames":
            for i, p in enumerate(sub.files["frames"]):
                out[f"frame_{i:04d}"] = _relative(p, sub)
        return out

    def run(self, ctx: JobContext) -> JobOutput:
        from ...spin_rate.pipeline import load_input, run
        from ...spin_rate.report import strip_png

        seq = _load(ctx.inputs, load_input)
        opts = EstimateOptions.model_validate(ctx.options)
        if opts.return_tracks is None:
            opts = opts.model_copy(update={"return_tracks": True})
        result = run(seq, opts, progress=ctx.progress).to_json()
        ctx.progress("writing", 0.95)
        ctx.output_path(STRIP_FILE).write_bytes(strip_png(seq, result))
        return JobOutput(result=result, artifacts={"strip": STRIP_FILE})

    def report(self, job: FinishedJob) -> str:
        from ...spin_rate.pipeline import load_input
        from ...spin_rate.report import build_report

        return build_report(_load(job.inputs, load_input), job.result)


def _load(inputs: Mapping[str, Path], load_input: Any) -> Any:
    frames = {p.name: p for k, p in inputs.items() if k.startswith("frame_")}
    return load_input(inputs["meta"], frames or None)


def _relative(path: Path, sub: Submission) -> str:
    return str(path.relative_to(sub.job_dir)) if path.is_relative_to(sub.job_dir) else str(path)
