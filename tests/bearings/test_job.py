"""The job adapter on its own (the service's routes are tested once the registry lists it):
accept validates everything up front, run gives the result the client model reads, report is
one HTML page."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tumblescan.bearings.inputs import Limits
from tumblescan.bearings.options import EstimateOptions
from tumblescan.bearings.simulate import SimulationConfig, invalid_variants, simulate
from tumblescan.errors import InputError
from tumblescan.jobs.kind import FinishedJob, JobContext, Submission
from tumblescan.jobs.kinds.bearings import BEARINGS_INPUT, Bearings
from tumblescan_client.results.bearings import BearingsResult as ClientResult

SIM = simulate(SimulationConfig(scene="paper", seed=2, frames=3, clutter=0.4))


def submission(tmp_path: Path, payload: object = None, files: dict[str, list[Path]] | None = None) -> Submission:
    return Submission(
        form=BEARINGS_INPUT,
        options=EstimateOptions(),
        limits=Limits(),
        job_dir=tmp_path,
        files=files or {},
        payload=payload,
    )


def run(kind: Bearings, tmp_path: Path, inputs: dict[str, str], options: dict | None = None) -> dict:
    stages: list[str] = []
    ctx = JobContext(
        job_id="j1",
        options=options or {},
        inputs={k: tmp_path / v for k, v in inputs.items()},
        output_path=lambda name: tmp_path / name,
        report=lambda stage, f: stages.append(stage),
    )
    out = kind.run(ctx)
    assert "associating" in stages or "matching (paper)" in stages
    return out.result


def test_json_input_is_validated_stored_run_and_reported(tmp_path: Path) -> None:
    kind = Bearings()
    assert kind.form_of({}, SIM.input) is BEARINGS_INPUT
    inputs = kind.accept(submission(tmp_path, payload=SIM.input))
    assert inputs == {"input": "input.json"}
    result = run(kind, tmp_path, inputs)
    parsed = ClientResult.model_validate(json.loads(json.dumps(result, allow_nan=False)))
    assert parsed.status == "succeeded" and len(parsed.frames) == 3
    assert parsed.summary is not None and parsed.summary.targets >= 12
    assert any(len(v) == 3 for v in parsed.targets_by_track().values())  # tracks span frames
    html = kind.report(FinishedJob("j1", result, {}, {"input": tmp_path / "input.json"}, {}))
    assert html.startswith("<!DOCTYPE html>") and "bearings-3d" in html and "Unassociated" in html


def test_uploaded_file_and_the_paper_method(tmp_path: Path) -> None:
    kind = Bearings()
    upload = tmp_path / "upload-input"
    upload.write_text(json.dumps(SIM.input))
    files = {"input": [upload]}
    assert kind.form_of(files, None) is BEARINGS_INPUT
    inputs = kind.accept(submission(tmp_path, files=files))
    assert inputs == {"input": "upload-input"}
    result = run(kind, tmp_path, inputs, {"method": "paper"})
    assert result["summary"]["method"] == "paper"


@pytest.mark.parametrize(("name", "text", "field"), invalid_variants(SIM.input)[:40:4])
def test_bad_input_is_refused_at_accept_naming_the_field(tmp_path: Path, name: str, text: str, field: str) -> None:
    upload = tmp_path / "bad"
    upload.write_text(text)
    with pytest.raises(InputError) as err:
        Bearings().accept(submission(tmp_path, files={"input": [upload]}))
    assert err.value.code == "invalid_input" and err.value.field == field


def test_wrong_upload_fields_are_refused(tmp_path: Path) -> None:
    kind = Bearings()
    with pytest.raises(InputError) as err:
        kind.form_of({"file": [tmp_path / "x"]}, None)
    assert err.value.field == "file"
    with pytest.raises(InputError) as err:
        kind.form_of({}, None)
    assert err.value.field == "input"


def test_limits_refuse_a_large_input_as_too_large(tmp_path: Path) -> None:
    sub = submission(tmp_path, payload=SIM.input)
    sub.limits = Limits(max_detections_total=5)
    with pytest.raises(InputError) as err:
        Bearings().accept(sub)
    assert err.value.code == "too_large"
