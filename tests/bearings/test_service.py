"""The bearings kind through a real service: published description, JSON input and upload
end to end (result typed by the client, report), bad input a 422 naming the field."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from tumblescan.bearings.result import BearingsResult
from tumblescan.bearings.score import score
from tumblescan.bearings.simulate import SimulationConfig, invalid_variants, simulate
from tumblescan_client import Client
from tumblescan_client.results import BearingsResult as ClientResult

from ..live import serve, wait_job

SIM = simulate(SimulationConfig(scene="paper", seed=21, frames=4, clutter=0.4, p_miss=0.1))


@pytest.fixture(scope="module")
def url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    with serve(tmp_path_factory.mktemp("bearings") / "data", workers=1) as base:
        yield base


@pytest.fixture(scope="module")
def http(url: str) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=url, timeout=30) as c:
        yield c


def test_the_kind_is_published(http: httpx.Client) -> None:
    assert "bearings" in {k["name"] for k in http.get("/v1/kinds").json()}
    kind = http.get("/v1/kinds/bearings").json()
    (form,) = kind["forms"]
    assert form["json_input"] and [p["name"] for p in form["parts"]] == ["input"]
    assert {"method", "gate_chi2", "link_tracks"} <= set(form["options_schema"]["properties"])
    assert kind["result_schema"] == json.loads(json.dumps(BearingsResult.model_json_schema()))
    assert kind["limits"]["max_detections_per_station_frame"] == 10_000


def test_json_input_job_succeeds_with_a_typed_result_and_a_report(url: str, http: httpx.Client) -> None:
    with Client(url) as client:
        job = client.jobs.create("bearings", input=SIM.input, options={"method": "ml"})
        result = client.jobs.result(job.id, timeout=120)
    assert isinstance(result, ClientResult) and result.status == "succeeded"
    s = score(result.model_dump(by_alias=True), SIM.truth)
    assert s.clean_associated == s.clean > 5 and s.false_targets == 0
    report = http.get(f"/v1/jobs/{job.id}/artifacts/report")
    assert report.status_code == 200 and "bearings-3d" in report.text


def test_uploaded_input_job_succeeds(http: httpx.Client) -> None:
    files = {"input": ("scene.json", json.dumps(SIM.input).encode())}
    r = http.post("/v1/jobs/upload", data={"kind": "bearings", "options": json.dumps({"method": "paper"})}, files=files)
    assert r.status_code in (200, 201, 202), r.text
    done = wait_job(http, r.json()["id"])
    assert done["status"] == "succeeded", done
    assert done["result"]["summary"]["method"] == "paper"


@pytest.mark.parametrize(
    ("name", "text", "field"),
    [v for v in invalid_variants(SIM.input) if v[0] in ("el_above_90", "az_nan", "duplicate_station", "units_angle")],
)
def test_bad_upload_is_a_422_naming_the_field(http: httpx.Client, name: str, text: str, field: str) -> None:
    r = http.post("/v1/jobs/upload", data={"kind": "bearings"}, files={"input": ("bad.json", text.encode())})
    assert r.status_code == 422, r.text
    detail = r.json()["detail"]
    assert detail["code"] == "invalid_input" and field in detail["message"]


def test_bad_json_input_is_a_422_naming_the_field(http: httpx.Client) -> None:
    doc = json.loads(json.dumps(SIM.input))
    doc["stations"][1]["sigma_az_deg"] = 7.0
    r = http.post("/v1/jobs", json={"kind": "bearings", "input": doc})
    assert r.status_code == 422, r.text
    detail = r.json()["detail"]
    assert detail["code"] == "invalid_input" and detail["message"].startswith("stations[1].sigma_az_deg")
    r = http.post("/v1/jobs", json={"kind": "bearings", "input": SIM.input, "options": {"colour": 1}})
    assert r.status_code == 422 and "options.colour" in r.json()["detail"]["message"]


def test_a_too_large_input_is_refused(http: httpx.Client, tmp_path: Path) -> None:
    big = simulate(SimulationConfig(scene="swarm", seed=1, targets=10, frames=1)).input
    big["frames"][0]["detections"]["S1"] = [{"id": f"x{i}", "az_deg": 0.001 * i, "el_deg": 10.0} for i in range(10_001)]
    r = http.post("/v1/jobs", json={"kind": "bearings", "input": big})
    assert r.status_code == 413, r.text  # the digest's contract for too_large
    assert r.json()["detail"]["code"] == "too_large"


def test_cli_submit_uploads_a_bearings_input_and_waits(url: str, tmp_path: Path) -> None:
    import subprocess
    import sys

    path = tmp_path / "input.json"
    path.write_text(json.dumps(SIM.input))
    proc = subprocess.run(
        [sys.executable, "-m", "tumblescan", "submit", "--kind", "bearings", f"input={path}", "--wait", "--url", url],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    result = ClientResult.model_validate_json(proc.stdout)
    assert result.status == "succeeded" and len(result.frames) == 4


@pytest.mark.parametrize(
    ("options", "field", "message"),
    [
        ('{"method": "paper", "gate_chi2": 0.1}', "gate_chi2", "does not apply to method 'paper'"),
        ('{"method": "paper", "multi_frame": false}', "multi_frame", "does not apply to method 'paper'"),
        ('{"paper_gate_sigma": 3}', "paper_gate_sigma", "does not apply to method 'ml'"),
        ('{"method": "ml", "paper_radius_deg": 5}', "paper_radius_deg", "does not apply to method 'ml'"),
        ('{"link_tracks": false, "max_speed_m_s": 300}', "max_speed_m_s", "link_tracks is false"),
        ('{"max_speed_m_s": Infinity}', "max_speed_m_s", "finite number"),
        ('{"method": "paper", "paper_gate_sigma": Infinity}', "paper_gate_sigma", "finite number"),
        ('{"gate_chi2": NaN}', "gate_chi2", "finite number"),
    ],
)
def test_an_option_that_would_be_ignored_or_is_not_finite_is_a_422(
    http: httpx.Client, options: str, field: str, message: str
) -> None:
    # Raw text: NaN and Infinity are JSON tokens a client's encoder may refuse to write.
    body = '{"kind": "bearings", "input": ' + json.dumps(SIM.input) + ', "options": ' + options + "}"
    r = http.post("/v1/jobs", content=body, headers={"content-type": "application/json"})
    assert r.status_code == 422, r.text
    detail = r.json()["detail"]
    assert detail["field"] == f"options.{field}" and message in detail["message"], detail
    r = http.post("/v1/jobs/upload", data={"kind": "bearings", "options": options}, files=_upload())
    assert r.status_code == 422, r.text
    assert r.json()["detail"]["field"] == f"options.{field}"


def test_the_gate_below_the_clis_old_minimum_is_accepted(http: httpx.Client) -> None:
    r = http.post("/v1/jobs", json={"kind": "bearings", "input": SIM.input, "options": {"gate_chi2": 0.05}})
    assert r.status_code in (200, 201, 202), r.text


def _upload() -> dict[str, tuple[str, bytes]]:
    return {"input": ("scene.json", json.dumps(SIM.input).encode())}
