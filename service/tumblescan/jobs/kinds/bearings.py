"""The ``bearings`` job kind: many targets located from two infrared stations' bearings.

Thin by design: validation and the work are ``tumblescan.bearings``'s (shared with the CLI);
this adapter declares the kind and moves files. The input is one JSON document
(``tumblescan.bearings.input/1``), given as the JSON ``input`` of ``POST /v1/jobs`` or uploaded
as the one file part ``input``.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pydantic import BaseModel

from ...bearings.errors import InvalidBearingsInputError
from ...bearings.inputs import INPUT_SCHEMA, Limits
from ...bearings.options import EstimateOptions
from ...bearings.result import BearingsResult
from ..kind import ArtifactSpec, FinishedJob, InputForm, InputPart, JobContext, JobOutput, Submission

INPUT_FILE = "input.json"

BEARINGS_INPUT = InputForm(
    name="bearings",
    description=f"detections (azimuth, elevation) at two stations, frame by frame ({INPUT_SCHEMA})",
    options=EstimateOptions,
    parts=(InputPart("input", f"the {INPUT_SCHEMA} document", ("json",)),),
    json_input=True,
    json_schema={
        "type": "object",
        "description": f"a {INPUT_SCHEMA} document (see docs/bearings.md)",
        "properties": {
            "schema": {"const": INPUT_SCHEMA},
            "frame": {"enum": ["local_enu", "ecef"]},
            "units": {"type": "object"},
            "epoch_utc": {"type": "string"},
            "stations": {"type": "array", "minItems": 2, "maxItems": 2, "items": {"type": "object"}},
            "frames": {"type": "array", "minItems": 1, "items": {"type": "object"}},
        },
        "required": ["schema", "frame", "stations", "frames"],
    },
)


class Bearings:
    name = "bearings"
    title = "Many targets located from two infrared stations' bearings"
    forms: tuple[InputForm, ...] = (BEARINGS_INPUT,)
    result_model: type[BaseModel] = BearingsResult
    artifacts: tuple[ArtifactSpec, ...] = ()
    limits_model: type[BaseModel] = Limits

    def form_of(self, files: Mapping[str, list[Path]], payload: Any) -> InputForm:
        if payload is None:
            unknown = sorted(set(files) - {"input"})
            if unknown:
                raise InvalidBearingsInputError(
                    f"{unknown[0]} is not an upload field of bearings (the one field is 'input')", field=unknown[0]
                )
            if len(files.get("input", [])) != 1:
                raise InvalidBearingsInputError(
                    f"input: upload exactly one {INPUT_SCHEMA} JSON file as 'input'", field="input"
                )
        return BEARINGS_INPUT

    def accept(self, sub: Submission) -> dict[str, str]:
        from ...bearings.inputs import parse_input, read_input

        limits = sub.limits
        assert isinstance(limits, Limits)
        if sub.payload is not None:
            # Validated in full now, so a bad input is a 422 rather than a failed job.
            parse_input(sub.payload, limits)
            path = sub.save(INPUT_FILE, json.dumps(sub.payload, allow_nan=False).encode())
        else:
            path = sub.files["input"][0]
            read_input(path, limits)
        return {"input": str(path.relative_to(sub.job_dir))}

    def run(self, ctx: JobContext) -> JobOutput:
        from ...bearings.pipeline import estimate_file

        _, result = estimate_file(
            ctx.inputs["input"], EstimateOptions.model_validate(ctx.options), progress=ctx.progress
        )
        return JobOutput(result=result)

    def report(self, job: FinishedJob) -> str:
        from ...bearings.inputs import read_input
        from ...bearings.report import build_report

        return build_report(read_input(job.inputs["input"]), job.result, title=f"Job {job.id}: bearings")
