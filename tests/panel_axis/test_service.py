"""panel-axis through the service: upload -> job succeeds with its overlay and report; bad input is
a 422 naming the field; an input the job can only judge by running fails with the kind's code."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest

from tumblescan_client import result_model

from ..live import serve, wait_job


@pytest.fixture(scope="module")
def http(tmp_path_factory: pytest.TempPathFactory) -> Iterator[httpx.Client]:
    with serve(tmp_path_factory.mktemp("panel") / "data") as url, httpx.Client(base_url=url, timeout=30) as c:
        yield c


def _files(d: Path, meta: dict[str, object] | None = None) -> dict[str, tuple[str, bytes]]:
    meta_bytes = json.dumps(meta).encode() if meta is not None else (d / "meta.json").read_bytes()
    return {"meta": ("meta.json", meta_bytes), "image": ("image.png", (d / "image.png").read_bytes())}


def test_the_kind_is_published(http: httpx.Client) -> None:
    r = http.get("/v1/kinds/panel-axis")
    assert r.status_code == 200
    body = r.json()
    assert body["name"] == "panel-axis"
    assert [p["name"] for p in body["forms"][0]["parts"]] == ["meta", "image"]


def test_upload_runs_to_a_result_near_the_truth(http: httpx.Client, near_noisy: Path) -> None:
    r = http.post(
        "/v1/jobs/upload", data={"kind": "panel-axis", "options": json.dumps({"seed": 3})}, files=_files(near_noisy)
    )
    assert r.status_code in (200, 201, 202), r.text
    done = wait_job(http, r.json()["id"])
    assert done["status"] == "succeeded", done
    result = result_model("panel-axis").model_validate(done["result"])
    truth = json.loads((near_noisy / "truth.json").read_text())
    err = np.degrees(np.arccos(min(1.0, abs(float(np.dot(result.axis.camera, truth["axis_camera"]))))))  # type: ignore[attr-defined,unused-ignore]
    assert err <= max(0.5, 3 * truth["sigma_crlb_deg"])
    overlay = http.get(f"/v1/jobs/{done['id']}/artifacts/overlay")
    assert overlay.status_code == 200 and overlay.content[:8] == b"\x89PNG\r\n\x1a\n"
    report = http.get(f"/v1/jobs/{done['id']}/artifacts/report")
    assert report.status_code == 200 and "Panel axis" in report.text


def test_bad_meta_is_422_naming_the_field(http: httpx.Client, near_noisy: Path) -> None:
    meta = json.loads((near_noisy / "meta.json").read_text())
    meta["camera"]["cx_px"] = 5000.0
    r = http.post("/v1/jobs/upload", data={"kind": "panel-axis"}, files=_files(near_noisy, meta))
    assert r.status_code == 422
    detail = r.json()["detail"]
    assert detail["field"] == "camera.cx_px" and detail["code"] == "invalid_input"


def test_an_image_that_is_not_one_is_422_unreadable_image(http: httpx.Client, near_noisy: Path) -> None:
    files = _files(near_noisy)
    files["image"] = ("image.png", b"\x89PNG\r\n\x1a\n" + b"\0" * 200)
    r = http.post("/v1/jobs/upload", data={"kind": "panel-axis"}, files=files)
    assert r.status_code == 422, r.text
    detail = r.json()["detail"]
    assert detail["code"] == "unreadable_image" and detail["field"] == "image"


def test_a_missing_part_and_an_unknown_option_are_422(http: httpx.Client, near_noisy: Path) -> None:
    files = _files(near_noisy)
    del files["image"]
    r = http.post("/v1/jobs/upload", data={"kind": "panel-axis"}, files=files)
    assert r.status_code == 422 and r.json()["detail"]["field"] == "image"
    r = http.post(
        "/v1/jobs/upload",
        data={"kind": "panel-axis", "options": json.dumps({"strategy": "lm"})},
        files=_files(near_noisy),
    )
    assert r.status_code == 422 and "strategy" in r.json()["detail"]["message"]


def test_a_blank_image_fails_the_job_with_no_target(http: httpx.Client, near_noisy: Path, tmp_path: Path) -> None:
    from tumblescan.imaging.image_io import write_image

    meta = json.loads((near_noisy / "meta.json").read_text())
    rng = np.random.default_rng(0)
    write_image(tmp_path / "image.png", rng.poisson(6.0, (480, 640)).astype(np.uint8))
    r = http.post("/v1/jobs/upload", data={"kind": "panel-axis"}, files=_files(tmp_path, meta))
    assert r.status_code in (200, 201, 202), r.text
    done = wait_job(http, r.json()["id"])
    assert done["status"] == "failed" and done["error"]["code"] == "no_target", done


def test_a_bool_for_a_number_is_422_naming_the_field(http: httpx.Client, near_noisy: Path) -> None:
    # "fx_px": true was a focal length of 1 px: 202, and the job succeeded with a wrong tilt.
    meta = json.loads((near_noisy / "meta.json").read_text())
    meta["camera"]["fx_px"] = True
    r = http.post("/v1/jobs/upload", data={"kind": "panel-axis"}, files=_files(near_noisy, meta))
    assert r.status_code == 422, r.text
    detail = r.json()["detail"]
    assert detail["field"] == "camera.fx_px" and detail["code"] == "invalid_input" and "not true" in detail["message"]


@pytest.mark.parametrize(
    ("options", "field", "words"),
    [
        ('{"weak_snr": Infinity}', "options.weak_snr", "finite number"),
        ('{"min_line_px": NaN}', "options.min_line_px", "finite number"),
        ('{"method": "paper", "require_axis": true}', "options.require_axis", "does not apply to method 'paper'"),
    ],
)
def test_bad_options_are_422_at_submission(
    http: httpx.Client, near_noisy: Path, options: str, field: str, words: str
) -> None:
    r = http.post("/v1/jobs/upload", data={"kind": "panel-axis", "options": options}, files=_files(near_noisy))
    assert r.status_code == 422, r.text
    detail = r.json()["detail"]
    assert detail["field"] == field and words in detail["message"], detail
