"""The ``marker-pose-graph`` job kind (thin: validation and work are in ``marker_pose.pipeline``)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pydantic import BaseModel

from ..kind import ArtifactSpec, FinishedJob, InputForm, InputPart, JobContext, JobOutput, Submission

MARKERS_FILE = "input-markers.json"


def _options() -> type[BaseModel]:
    from ...marker_pose.options import MarkerPoseOptions

    return MarkerPoseOptions


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
    )
    result_model = _result()
    artifacts: tuple[ArtifactSpec, ...] = ()  # the HTML report is served by the job layer
    limits_model = _limits()

    def form_of(self, files: Mapping[str, list[Path]], payload: Any) -> InputForm:
        # Unknown fields and a missing 'markers' part are the service's checks (one form, JSON or upload).
        return self.forms[0]

    def accept(self, sub: Submission) -> dict[str, str]:
        from ...marker_pose.markers_io import markers_from_json
        from ...marker_pose.pipeline import load_input

        options = sub.options
        if sub.payload is not None:
            markers_from_json(sub.payload, point_sigma_m=getattr(options, "point_sigma_m", None), limits=sub.limits)  # type: ignore[arg-type]
            sub.save(MARKERS_FILE, json.dumps(sub.payload).encode())
            return {"markers": MARKERS_FILE}
        layout = sub.files.get("layout", [None])[0]
        load_input(sub.files["markers"][0], layout, options, sub.limits)  # type: ignore[arg-type]
        out = {"markers": str(sub.files["markers"][0].relative_to(sub.job_dir))}
        if layout is not None:
            out["layout"] = str(layout.relative_to(sub.job_dir))
        return out

    def run(self, ctx: JobContext) -> JobOutput:
        from ...marker_pose.options import MarkerPoseOptions
        from ...marker_pose.pipeline import run

        options = MarkerPoseOptions.model_validate(ctx.options)
        result = run(ctx.inputs["markers"], layout=ctx.inputs.get("layout"), options=options, progress=ctx.progress)
        return JobOutput(result=result.model_dump(mode="json"))

    def report(self, job: FinishedJob) -> str:
        from ...marker_pose.report import build_report
        from ...marker_pose.result import MarkerPoseResult

        return build_report(MarkerPoseResult.model_validate(job.result), f"Job {job.id}")
