"""spin-from-images through a live service: meta + frames upload and zip upload run to a result near
the truth; bad input is a 422 naming the field or file; a blank sequence fails with no_target."""

from __future__ import annotations

import io
import json
import zipfile
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from tumblescan_client.results import SpinResult, result_model

from ..live import serve, wait_job


@pytest.fixture(scope="module")
def http(tmp_path_factory: pytest.TempPathFactory) -> Iterator[httpx.Client]:
    with serve(tmp_path_factory.mktemp("spin") / "data") as url, httpx.Client(base_url=url, timeout=60) as c:
        yield c


def _files(d: Path, meta: dict[str, object] | None = None) -> list[tuple[str, tuple[str, bytes]]]:
    meta_bytes = json.dumps(meta).encode() if meta is not None else (d / "meta.json").read_bytes()
    files = [("meta", ("meta.json", meta_bytes))]
    for p in sorted((d / "frames").iterdir()):
        files.append(("frames", (p.name, p.read_bytes())))
    return files


def test_the_kind_is_published(http: httpx.Client) -> None:
    body = http.get("/v1/kinds/spin-from-images").json()
    assert body["name"] == "spin-from-images"
    assert [f["name"] for f in body["forms"]] == ["frames", "archive"]


def test_upload_runs_to_a_result_near_the_truth(http: httpx.Client, los_seq: Path) -> None:
    r = http.post("/v1/jobs/upload", data={"kind": "spin-from-images"}, files=_files(los_seq))
    assert r.status_code in (200, 201, 202), r.text
    done = wait_job(http, r.json()["id"], timeout_s=120)
    assert done["status"] == "succeeded", done
    assert result_model("spin-from-images") is SpinResult
    result = SpinResult.model_validate(done["result"])
    truth = json.loads((los_seq / "truth.json").read_text())
    assert abs(result.spin.rate_deg_s - truth["rate_deg_s"]) <= 4 * result.spin.sigma_rate_deg_s + 0.002
    strip = http.get(f"/v1/jobs/{done['id']}/artifacts/strip")
    assert strip.status_code == 200 and strip.content[:8] == b"\x89PNG\r\n\x1a\n"
    report = http.get(f"/v1/jobs/{done['id']}/artifacts/report")
    assert report.status_code == 200 and "spin-from-images" in report.text


def test_a_zip_upload_runs(http: httpx.Client, los_seq: Path) -> None:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for p in los_seq.rglob("*"):
            if p.is_file() and p.name != "truth.json":
                zf.write(p, p.relative_to(los_seq))
    r = http.post("/v1/jobs/upload", data={"kind": "spin-from-images"}, files={"archive": ("seq.zip", buf.getvalue())})
    assert r.status_code in (200, 201, 202), r.text
    done = wait_job(http, r.json()["id"], timeout_s=120)
    assert done["status"] == "succeeded", done


def test_bad_meta_and_a_corrupt_frame_are_422(http: httpx.Client, los_seq: Path, corrupt_seq: Path) -> None:
    meta = json.loads((los_seq / "meta.json").read_text())
    del meta["camera"]["fx_px"]
    r = http.post("/v1/jobs/upload", data={"kind": "spin-from-images"}, files=_files(los_seq, meta))
    assert r.status_code == 422
    assert r.json()["detail"]["field"] == "camera.fx_px" and r.json()["detail"]["code"] == "invalid_input"
    r = http.post("/v1/jobs/upload", data={"kind": "spin-from-images"}, files=_files(corrupt_seq))
    assert r.status_code == 422
    detail = r.json()["detail"]
    assert detail["code"] == "unreadable_image" and detail["field"].startswith("frames.")
    files = _files(los_seq)[:-1]  # the last frame missing
    r = http.post("/v1/jobs/upload", data={"kind": "spin-from-images"}, files=files)
    assert r.status_code == 422 and r.json()["detail"]["field"].endswith(".file")
    # A frame meta.json does not list was once ignored silently (a wrong or renamed file).
    files = [*_files(los_seq), ("frames", ("stray.png", _files(los_seq)[-1][1][1]))]
    r = http.post("/v1/jobs/upload", data={"kind": "spin-from-images"}, files=files)
    assert r.status_code == 422, r.text
    detail = r.json()["detail"]
    assert detail["field"] == "frames" and "stray.png" in detail["message"]


def test_blank_frames_fail_the_job_with_no_target(http: httpx.Client, blank_seq: Path) -> None:
    r = http.post("/v1/jobs/upload", data={"kind": "spin-from-images"}, files=_files(blank_seq))
    assert r.status_code in (200, 201, 202), r.text
    done = wait_job(http, r.json()["id"], timeout_s=60)
    assert done["status"] == "failed"
    assert done["error"]["code"] == "no_target"


@pytest.mark.parametrize(
    ("path", "value", "field"),
    [
        ("camera.fx_px", True, "camera.fx_px"),  # was a 1 px focal length and a confident wrong rate
        ("camera.cx_px", 1e6, "camera.cx_px"),  # was 202 and 2.09 ± 96 deg/s
        ("exposure_s", 1e9, "exposure_s"),
        ("epoch_utc", "yesterday", "epoch_utc"),
    ],
)
def test_meta_of_the_wrong_type_or_out_of_range_is_422(
    http: httpx.Client, los_seq: Path, path: str, value: object, field: str
) -> None:
    meta = json.loads((los_seq / "meta.json").read_text())
    *parents, last = path.split(".")
    node = meta
    for key in parents:
        node = node[key]
    node[last] = value
    r = http.post("/v1/jobs/upload", data={"kind": "spin-from-images"}, files=_files(los_seq, meta))
    assert r.status_code == 422, r.text
    assert r.json()["detail"]["field"] == field


def test_options_of_the_wrong_type_are_422(http: httpx.Client, los_seq: Path) -> None:
    data = {"kind": "spin-from-images", "options": json.dumps({"return_tracks": "yes"})}
    r = http.post("/v1/jobs/upload", data=data, files=_files(los_seq))
    assert r.status_code == 422, r.text
    assert r.json()["detail"]["field"] == "options.return_tracks"
