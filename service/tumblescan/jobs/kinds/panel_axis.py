"""The ``panel-axis`` job kind: the solar-panel axis from one optical image (upload parts ``meta``
and ``image``). Thin: validation and the work are ``tumblescan.panel_axis.pipeline``'s."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from ...errors import InputError, LimitExceededError
from ...panel_axis.options import EstimateOptions
from ...panel_axis.result import PanelAxisResult
from ..kind import ArtifactSpec, FinishedJob, InputForm, InputPart, JobContext, JobOutput, Submission

OVERLAY_FILE = "overlay.png"


class PanelAxisLimits(BaseModel):
    """Input sizes a deployment accepts."""

    model_config = ConfigDict(extra="forbid")

    max_pixels: int = Field(64_000_000, gt=0, description="largest image (pixels)")
    max_image_bytes: int = Field(512_000_000, gt=0, description="largest image file")


IMAGE_FORM = InputForm(
    name="image",
    description="one grayscale (or RGB) PNG/TIFF image, 8 or 16 bit, and its meta.json "
    "(schema tumblescan.panel_axis.input/1: camera, optional pointing, station and panel prior)",
    options=EstimateOptions,
    parts=(
        InputPart("meta", "meta.json (its 'image' field is ignored: the image is the 'image' part)", ("json",)),
        InputPart("image", "the image", ("png", "tiff")),
    ),
)


class PanelAxis:
    name = "panel-axis"
    title = "A solar-panel axis from one optical image"
    forms: tuple[InputForm, ...] = (IMAGE_FORM,)
    result_model: type[BaseModel] = PanelAxisResult
    artifacts: tuple[ArtifactSpec, ...] = (
        ArtifactSpec("overlay", "image/png", "the image with the detected edges and the estimated axis drawn on it"),
    )
    limits_model: type[BaseModel] = PanelAxisLimits

    def form_of(self, files: Mapping[str, list[Path]], payload: Any) -> InputForm:
        for part in ("meta", "image"):
            if part not in files:
                raise InputError(f"an upload needs '{part}'", field=part)
        return IMAGE_FORM

    def accept(self, sub: Submission) -> dict[str, str]:
        from ...panel_axis.pipeline import load_input

        limits = sub.limits
        assert isinstance(limits, PanelAxisLimits)
        image = sub.files["image"][0]
        if image.stat().st_size > limits.max_image_bytes:
            raise LimitExceededError(f"image: {image.stat().st_size} bytes is over the limit", field="image")
        data = load_input(sub.files["meta"][0], image)  # every invalid_input is a 422 now
        if data.gray.size > limits.max_pixels:
            raise LimitExceededError(
                f"image: {data.gray.size} px is over the {limits.max_pixels} px limit", field="image"
            )
        return {"meta": _relative(sub.files["meta"][0], sub), "image": _relative(image, sub)}

    def run(self, ctx: JobContext) -> JobOutput:
        from ...panel_axis.pipeline import load_input, run
        from ...panel_axis.report import overlay_png

        data = load_input(ctx.inputs["meta"], ctx.inputs["image"])
        result = run(data, EstimateOptions.model_validate(ctx.options), progress=ctx.progress).to_json()
        ctx.progress("writing", 0.95)
        ctx.output_path(OVERLAY_FILE).write_bytes(overlay_png(data.gray, data.meta, result))
        return JobOutput(result=result, artifacts={"overlay": OVERLAY_FILE})

    def report(self, job: FinishedJob) -> str:
        from ...panel_axis.pipeline import load_input
        from ...panel_axis.report import build_report

        data = load_input(job.inputs["meta"], job.inputs["image"])
        truth = None
        if "truth" in job.inputs:
            truth = json.loads(job.inputs["truth"].read_text())
        return build_report(data.gray, data.meta, job.result, truth)


def _relative(path: Path, sub: Submission) -> str:
    return str(path.relative_to(sub.job_dir)) if path.is_relative_to(sub.job_dir) else str(path)
