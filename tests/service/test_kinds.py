"""The generic job layer against a real service: kinds described from the registry, options
checked per input form, uploads by the kind's parts, artifacts by name."""

from __future__ import annotations

import json
import subprocess
import sys
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from tumblescan import MotionResult, TimedCloud, Tracks, simulate_frames, tracks_to_json, write_ply
from tumblescan.jobs.registry import kinds

from ..conftest import motion_for, tracks_for
from ..live import serve, wait_job


@pytest.fixture(scope="module")
def url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    with serve(tmp_path_factory.mktemp("kinds") / "data") as u:
        yield u


@pytest.fixture(scope="module")
def http(url: str) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=url, timeout=30) as c:
        yield c


@pytest.fixture(scope="module")
def frames_ply(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Coarse dense frames (64 x 64) of a simulated satellite."""
    from tumblescan import Scanner, Scene

    cloud = simulate_frames(motion_for(3), Scene(scanner=Scanner(lines=64, pixels=64)), seed=3)
    path = tmp_path_factory.mktemp("frames") / "frames.ply"
    write_ply(path, TimedCloud(cloud.xyz_m, cloud.t_s, {"frame": cloud.frame, "line": cloud.line}))
    return path


def test_kinds_lists_every_registered_kind(http: httpx.Client) -> None:
    r = http.get("/v1/kinds")
    assert r.status_code == 200
    listed = {k["name"]: k for k in r.json()}
    assert set(listed) == set(kinds()) and "linescan-motion" in listed
    assert listed["linescan-motion"]["url"].endswith("/v1/kinds/linescan-motion")


def test_a_kind_publishes_its_forms_options_result_and_artifacts(http: httpx.Client) -> None:
    kind = http.get("/v1/kinds/linescan-motion").json()
    forms = {f["name"]: f for f in kind["forms"]}
    assert set(forms) == {"tracks", "frames"}
    assert forms["tracks"]["json_input"] and not forms["frames"]["json_input"]
    assert [p["name"] for p in forms["frames"]["parts"]] == ["file", "truth"]
    assert "strategy" in forms["tracks"]["options_schema"]["properties"]
    assert "strategy" not in forms["frames"]["options_schema"]["properties"]
    assert "dense" in forms["frames"]["options_schema"]["properties"]
    assert kind["result_schema"] == json.loads(json.dumps(MotionResult.model_json_schema()))
    assert [a["name"] for a in kind["artifacts"]] == ["cloud"]
    assert kind["limits"]["max_cloud_points"] > 0


def test_an_unknown_kind_is_404_or_422_naming_it(http: httpx.Client, tmp_path: Path) -> None:
    r = http.get("/v1/kinds/no-such-kind")
    assert r.status_code == 404 and "no job kind 'no-such-kind'" in r.json()["detail"]["message"]
    r = http.post("/v1/jobs/upload", data={"kind": "no-such-kind"}, files={"file": ("t.json", b"{}")})
    assert r.status_code == 422
    detail = r.json()["detail"]
    assert detail["code"] == "unknown_kind" and detail["field"] == "kind" and "linescan-motion" in detail["message"]


def test_an_option_of_the_other_form_is_refused_by_name(http: httpx.Client, frames_ply: Path) -> None:
    files = {"file": ("frames.ply", frames_ply.read_bytes())}
    r = http.post("/v1/jobs/upload", files=files, data={"options": json.dumps({"strategy": "lm", "seed": 1})})
    assert r.status_code == 422, r.text
    detail = r.json()["detail"]
    assert detail["code"] == "invalid_options"
    assert "options.strategy: does not apply to frames input (an option of tracks input)" in detail["message"]
    r = http.post("/v1/jobs", json={"input": {"tracks": tracks_doc(1)}, "options": {"dense": {}}})
    assert r.status_code == 422 and "options.dense: does not apply to tracks input" in r.json()["detail"]["message"]
    r = http.post("/v1/jobs", json={"input": {"tracks": tracks_doc(1)}, "options": {"nonsense": 1}})
    assert r.status_code == 422 and "options.nonsense: unknown option" in r.json()["detail"]["message"]


def test_upload_fields_are_checked_against_the_kind(http: httpx.Client, frames_ply: Path) -> None:
    r = http.post("/v1/jobs/upload", files={"picture": ("x.png", b"\x89PNG\r\n\x1a\n")})
    detail = r.json()["detail"]
    assert r.status_code == 422 and detail["field"] == "picture" and "unknown upload field" in detail["message"]
    two = [("file", ("a.ply", frames_ply.read_bytes())), ("file", ("b.ply", frames_ply.read_bytes()))]
    r = http.post("/v1/jobs/upload", files=two)
    assert r.status_code == 422 and r.json()["detail"]["message"] == "'file' takes one file; got 2"
    r = http.post("/v1/jobs/upload", data={"kind": "linescan-motion", "file": "not a file"})
    assert r.status_code == 422 and r.json()["detail"]["field"] == "file"


def test_artifacts_are_listed_and_served_by_name(http: httpx.Client, tmp_path: Path) -> None:
    _, tracks = tracks_for(5)
    cloud = _cloud_near(tracks)
    write_ply(tmp_path / "c.ply", cloud)
    files = {
        "file": ("t.json", json.dumps(tracks_to_json(tracks)).encode()),
        "cloud": ("c.ply", (tmp_path / "c.ply").read_bytes()),
    }
    job = http.post("/v1/jobs/upload", files=files).json()
    done = wait_job(http, job["id"])
    assert done["status"] == "succeeded", done
    listing = http.get(f"/v1/jobs/{job['id']}/artifacts").json()
    assert {a["name"]: a["media_type"] for a in listing} == {"cloud": "application/octet-stream", "report": "text/html"}
    by_name = http.get(f"/v1/jobs/{job['id']}/artifacts/cloud")
    assert by_name.status_code == 200 and by_name.content == http.get(f"/v1/jobs/{job['id']}/cloud").content
    report = http.get(f"/v1/jobs/{job['id']}/artifacts/report")
    assert report.status_code == 200 and report.text.startswith("<!DOCTYPE html>")
    missing = http.get(f"/v1/jobs/{job['id']}/artifacts/nothing")
    assert missing.status_code == 404 and "no artifact 'nothing'" in missing.json()["detail"]["message"]


def test_artifacts_of_an_unfinished_job_are_409(http: httpx.Client) -> None:
    job = http.post("/v1/jobs", json={"input": {"tracks": tracks_doc(2)}}).json()
    r = http.get(f"/v1/jobs/{job['id']}/artifacts")
    assert r.status_code in (200, 409)  # it may already have finished on a fast machine
    if r.status_code == 409:
        assert "once it has succeeded" in r.json()["detail"]["message"]
    wait_job(http, job["id"])


def tracks_doc(seed: int) -> dict[str, Any]:
    return tracks_to_json(tracks_for(seed)[1])


def _cloud_near(tracks: Tracks) -> TimedCloud:
    """500 points around the target, at times within the tracks' span."""
    rng = np.random.default_rng(0)
    t_s = np.sort(rng.uniform(tracks.t_s.min(), tracks.t_s.max(), 500))
    return TimedCloud(rng.normal(size=(500, 3)) + tracks.xyz_m.mean(axis=0), t_s, {})


def test_every_kind_refuses_garbage_in_every_part_with_a_422(http: httpx.Client) -> None:
    # Driven by GET /v1/kinds alone, so each new kind is covered from the day it is registered.
    rng = np.random.default_rng(7)
    for summary in http.get("/v1/kinds").json():
        kind = http.get(summary["url"]).json()
        for form in kind["forms"]:
            for part in form["parts"]:
                junk = [(p["name"], (f"{p['name']}.bin", rng.bytes(300))) for p in form["parts"] if p["required"]]
                junk += [(part["name"], (f"{part['name']}.bin", b"\x00\x01garbage"))] if not part["required"] else []
                r = http.post("/v1/jobs/upload", data={"kind": kind["name"]}, files=junk)
                assert r.status_code == 422, (kind["name"], form["name"], part["name"], r.text)
                assert r.json()["detail"]["field"], r.text
            if form["json_input"]:
                r = http.post("/v1/jobs", json={"kind": kind["name"], "input": {"nonsense": [1, 2, 3]}})
                assert r.status_code == 422 and r.json()["detail"]["field"], r.text
        if not any(form["json_input"] for form in kind["forms"]):
            r = http.post("/v1/jobs", json={"kind": kind["name"], "input": {"nonsense": [1, 2, 3]}})
            detail = r.json()["detail"]
            assert r.status_code == 422 and detail["field"] == "input", r.text
            assert "takes its input as an upload" in detail["message"], r.text


def test_tracks_the_forced_closed_form_cannot_start_fail_with_a_code(http: httpx.Client) -> None:
    # Three corners seen in every frame would do; here the third is seen in frames 0-2 only.
    doc = tracks_doc(6)
    counts = Counter(o["track"] for o in doc["observations"])
    ids = [t for t, _ in counts.most_common(3)]
    keep = [o for o in doc["observations"] if o["track"] in ids[:2] or (o["track"] == ids[2] and o["frame"] < 3)]
    job = http.post(
        "/v1/jobs", json={"input": {"tracks": {**doc, "observations": keep}}, "options": {"strategy": "lm"}}
    )
    assert job.status_code == 202, job.text
    done = wait_job(http, job.json()["id"])
    assert done["status"] == "failed" and done["error"]["code"] == "not_initializable", done
    assert "use strategy 'auto' or 'swarm'" in done["error"]["message"]


def cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "tumblescan", *args], capture_output=True, text=True, timeout=300)


def test_submit_any_kind_by_its_parts_and_fetch_every_artifact(url: str, tmp_path: Path) -> None:
    (tmp_path / "t.json").write_text(json.dumps(tracks_doc(8)))
    out = tmp_path / "artifacts"
    proc = cli("submit", "--kind", "linescan-motion", f"file={tmp_path / 't.json'}", "--wait", "--artifacts", str(out),
               "--url", url)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert MotionResult.model_validate_json(proc.stdout).spin.rate_deg_s > 0
    assert (out / "report.html").read_text().startswith("<!DOCTYPE html>")
    proc = cli("submit", "--kind", "no-such-kind", str(tmp_path / "t.json"), "--url", url)
    assert proc.returncode == 2 and proc.stderr.startswith("error: ") and proc.stderr.count("\n") == 1
    proc = cli("submit", str(tmp_path / "missing.json"), "--url", url)
    assert proc.returncode == 2 and proc.stderr == f"error: no such file: {tmp_path / 'missing.json'}\n"


def test_a_cloud_with_tracks_must_be_a_ply(http: httpx.Client, tmp_path: Path) -> None:
    np.savez(tmp_path / "c.npz", xyz_m=np.zeros((10, 3)), t_s=np.arange(10.0))
    files = {
        "file": ("t.json", json.dumps(tracks_doc(9)).encode()),
        "cloud": ("c.npz", (tmp_path / "c.npz").read_bytes()),
    }
    r = http.post("/v1/jobs/upload", files=files)
    detail = r.json()["detail"]
    assert r.status_code == 422 and detail["field"] == "cloud"
    assert detail["message"] == "'cloud' must be a PLY with per-point times"
