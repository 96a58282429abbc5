"""The ``marker-pose-graph`` job kind (thin: validation and work are in ``marker_pose.pipeline``)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from pydantic import BaseModel

from ..kind import ArtifactSpec, FinishedJob, InputForm, InputPart, JobContext, JobOutput, Submission, form_named

if TYPE_CHECKING:
    from ...marker_pose.options import MarkerPoseLimits, MarkerPoseOptions

MARKERS_FILE = "input-markers.json"
TAGS_FILE = "input-tags.json"
TAGS_FORMAT = "tumblescan.tags.v1"


def _options() -> type[BaseModel]:
    from ...marker_pose.options import MarkerPoseOptions

    return MarkerPoseOptions


def _tag_options() -> type[BaseModel]:
    from ...marker_pose.options import TagPoseOptions

    return TagPoseOptions


def _image_options() -> type[BaseModel]:
    from ...marker_pose.options import ImagePoseOptions

    return ImagePoseOptions


def _limits() -> type[BaseModel]:
    from ...marker_pose.options import MarkerPoseLimits

    return MarkerPoseLimits


def _result() -> type[BaseModel]:
    from ...marker_pose.result import MarkerPoseResult

    return MarkerPoseResult


class MarkerPoseGraph:
    name = "marker-pose-graph"
    title = "Target pose from tracked markers, refined by an SE(3) pose graph"
    forms: tuple[InputForm, ...] = (
        InputForm(
            name="markers",
            description="level A: 3D marker coordinates per frame and track (tumblescan.markers.v1 JSON or CSV)",
            options=_options(),
            parts=(
                InputPart("markers", "marker observations", ("json", "csv")),
                InputPart("layout", "marker layout {markers: [{id, xyz}]}", ("json",), required=False),
            ),
            json_input=True,
            json_schema={
                "type": "object",
                "description": "a tumblescan.markers.v1 document (see docs/marker_pose.md)",
                "properties": {"format": {"const": "tumblescan.markers.v1"}, "observations": {"type": "array"}},
                "required": ["observations"],
            },
        ),
        InputForm(
            name="tags",
            description="level B: tag corner detections from calibrated cameras (tumblescan.tags.v1 JSON)",
            options=_tag_options(),
            parts=(InputPart("tags", "cameras, tag layout and corner detections (tumblescan.tags.v1)", ("json",)),),
            json_input=True,
            json_schema={
                "type": "object",
                "description": "a tumblescan.tags.v1 document (see docs/marker_pose.md)",
                "properties": {
                    "format": {"const": TAGS_FORMAT},
                    "cameras": {"type": "array"},
                    "tags": {"type": "object"},
                    "detections": {"type": "array"},
                },
                "required": ["format", "cameras", "tags", "detections"],
            },
        ),
        InputForm(
            name="images",
            description="level C: a zip of scene.json (level B without detections, with frames) and "
            "images/<camera>/<frame:06d>.png",
            options=_image_options(),
            parts=(InputPart("images", "zip of scene.json and images/<camera>/<frame:06d>.png", ("zip",)),),
        ),
    )
    result_model = _result()
    artifacts: tuple[ArtifactSpec, ...] = ()  # the HTML report is served by the job layer
    limits_model = _limits()

    def form_of(self, files: Mapping[str, list[Path]], payload: Any) -> InputForm:
        # A JSON input is a tags document by its format tag, else markers; an upload by its parts
        # (the service checks the parts each form requires).
        if payload is not None:
            is_tags = isinstance(payload, dict) and payload.get("format") == TAGS_FORMAT
            return form_named(self, "tags" if is_tags else "markers")
        if "images" in files:
            return form_named(self, "images")
        return form_named(self, "tags" if "tags" in files else "markers")

    def accept(self, sub: Submission) -> dict[str, str]:
        from ...marker_pose.estimate import body_frame_of
        from ...marker_pose.markers_io import markers_from_json
        from ...marker_pose.pipeline import load_input

        options = sub.options
        if sub.form.name == "tags":
            return self._accept_tags(sub)
        if sub.form.name == "images":
            from ...marker_pose.images_io import check_images, read_image_set

            archive = sub.files["images"][0]
            check_images(read_image_set(archive, sub.limits))  # type: ignore[arg-type]
            return {"images": str(archive.relative_to(sub.job_dir))}
        # Level A: the markers read and validated, and the frame the poses would be stated in.
        limits = cast("MarkerPoseLimits", sub.limits)
        marker_options = cast("MarkerPoseOptions", options)
        if sub.payload is not None:
            data = markers_from_json(sub.payload, point_sigma_m=marker_options.point_sigma_m, limits=limits)
            body_frame_of(data, marker_options)
            sub.save(MARKERS_FILE, json.dumps(sub.payload).encode())
            return {"markers": MARKERS_FILE}
        layout = sub.files.get("layout", [None])[0]
        body_frame_of(load_input(sub.files["markers"][0], layout, marker_options, limits), marker_options)
        out = {"markers": str(sub.files["markers"][0].relative_to(sub.job_dir))}
        if layout is not None:
            out["layout"] = str(layout.relative_to(sub.job_dir))
        return out

    def _accept_tags(self, sub: Submission) -> dict[str, str]:
        from ...marker_pose.tags_io import read_tags, tags_from_json

        if sub.payload is not None:
            tags_from_json(sub.payload, limits=sub.limits)  # type: ignore[arg-type]
            sub.save(TAGS_FILE, json.dumps(sub.payload).encode())
            return {"tags": TAGS_FILE}
        read_tags(sub.files["tags"][0], sub.limits)  # type: ignore[arg-type]
        return {"tags": str(sub.files["tags"][0].relative_to(sub.job_dir))}

    def run(self, ctx: JobContext) -> JobOutput:
        from ...marker_pose.options import ImagePoseOptions, MarkerPoseOptions, TagPoseOptions
        from ...marker_pose.pipeline import run, run_images, run_tags

        if "tags" in ctx.inputs:
            tag_result = run_tags(
                ctx.inputs["tags"], options=TagPoseOptions.model_validate(ctx.options), progress=ctx.progress
            )
            return JobOutput(result=tag_result.model_dump(mode="json"))
        if "images" in ctx.inputs:
            image_result = run_images(
                ctx.inputs["images"], options=ImagePoseOptions.model_validate(ctx.options), progress=ctx.progress
            )
            return JobOutput(result=image_result.model_dump(mode="json"))
        options = MarkerPoseOptions.model_validate(ctx.options)
        result = run(ctx.inputs["markers"], layout=ctx.inputs.get("layout"), options=options, progress=ctx.progress)
        return JobOutput(result=result.model_dump(mode="json"))

    def report(self, job: FinishedJob) -> str:
        from ...marker_pose.report import build_report
        from ...marker_pose.result import MarkerPoseResult

        return build_report(MarkerPoseResult.model_validate(job.result), f"Job {job.id}")
