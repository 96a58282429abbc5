"""Reports and pages: the HTML a user opens, checked in a real headless browser."""

from __future__ import annotations

import asyncio
import dataclasses
import io
import json
import re
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from tumblescan import Scanner, Scene, TimedCloud, simulate_frames, simulate_tracks, write_ply
from tumblescan.linescan.options import FramesOptions, TracksOptions
from tumblescan.linescan.pipeline import Outcome, estimate_frames, estimate_tracks
from tumblescan.linescan.report import ReportInputs, build_report
from tumblescan.linescan.report_text import fit_text
from tumblescan.linescan.tracks_io import write_tracks
from tumblescan.linescan.truth import errors_against, load_truth, motion_to_json
from tumblescan.target.motion import Motion

from ..browser import browser_page
from ..conftest import motion_for
from ..live import serve

ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts"


@pytest.fixture(scope="module")
def sim(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A simulated satellite: tracks, distorted frames (coarse scanner) and the truth."""
    out = tmp_path_factory.mktemp("reportsim")
    motion = motion_for(7)
    scene = Scene(scanner=Scanner(lines=128, pixels=128))
    tracks, _ = simulate_tracks(motion, Scene(), seed=7)
    cloud = simulate_frames(motion, scene, seed=7)
    write_tracks(out / "tracks.json", tracks)
    write_ply(out / "frames.ply", TimedCloud(cloud.xyz_m, cloud.t_s, {"frame": cloud.frame, "line": cloud.line}))
    (out / "truth.json").write_text(json.dumps({"motion": motion_to_json(motion)}))
    return out


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory, sim: Path) -> Iterator[tuple[str, dict[str, Any]]]:
    with serve(tmp_path_factory.mktemp("reportsvc") / "data") as url, httpx.Client(base_url=url, timeout=60) as http:
        files = {name: (name, (sim / name).read_bytes()) for name in ("tracks.json", "frames.ply", "truth.json")}
        r = http.post(
            "/v1/jobs/upload",
            files={"file": files["tracks.json"], "cloud": files["frames.ply"], "truth": files["truth.json"]},
        )
        assert r.status_code == 202, r.text
        job_id = r.json()["id"]
        deadline = time.monotonic() + 120
        while (job := http.get(f"/v1/jobs/{job_id}").json())["status"] not in ("succeeded", "failed", "cancelled"):
            assert time.monotonic() < deadline
            time.sleep(0.1)
        assert job["status"] == "succeeded", job
        yield url, job


def test_report_endpoint_is_one_self_contained_html_file(service: tuple[str, dict[str, Any]]) -> None:
    _, job = service
    r = httpx.get(job["artifacts"]["report"])
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    page = r.text
    # Works offline: plotly is inlined and nothing is fetched from elsewhere.
    assert "Plotly" in page
    import re

    markup = re.sub(r"<script[^>]*>.*?</script>", "", page, flags=re.S)
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:)?//""", markup), "the page loads something from elsewhere"
    assert "<script src" not in markup
    assert f"{job['result']['spin']['rate_deg_s']:.6f}" in page
    assert "truth" in page and "showing 40,000 of" not in page.split("data-field='decimation'")[0]


def test_report_and_job_list_in_a_real_browser(service: tuple[str, dict[str, Any]]) -> None:
    url, job = service
    ARTIFACTS.mkdir(exist_ok=True)
    asyncio.run(_check_in_browser(url, job))


async def _check_in_browser(url: str, job: dict[str, Any]) -> None:
    result = job["result"]
    async with browser_page() as page:
        requested: list[str] = []
        page.on("request", lambda req: requested.append(req.url))
        resp = await page.goto(f"{url}/")
        assert resp.status == 200
        row = page.locator(f"tr[data-job='{job['id']}']")
        assert "succeeded" in await row.inner_text()
        await row.locator("a").click()
        await page.wait_for_selector("#view3d canvas", timeout=30_000)

        # The summary shows exactly the API's values.
        async def field(name: str) -> str:
            return str(await page.locator(f"[data-field='{name}']").first.inner_text()).strip()

        assert await field("spin.rate_deg_s") == f"{result['spin']['rate_deg_s']:.6f}"
        assert await field("precession.rate_deg_s") == f"{result['precession']['rate_deg_s']:.6f}"
        assert await field("model") == result["model"]
        assert await field("spin.axis") == "[" + ", ".join(f"{v:.6f}" for v in result["spin"]["axis"]) + "]"
        assert (await field("validation.passed")).startswith("passed")
        assert "points" in await field("decimation")
        # The 3D view rendered: a WebGL canvas with varied pixels.
        has_gl = (
            "() => { const c = document.querySelector('#view3d canvas');"
            " return !!(c.getContext('webgl2') || c.getContext('webgl')); }"
        )
        assert await page.evaluate(has_gl)
        await page.wait_for_timeout(1000)
        png = await page.locator("#view3d").screenshot()
        from PIL import Image

        colours = Image.open(io.BytesIO(png)).convert("RGB").getcolors(maxcolors=1 << 20)
        assert colours is not None and len(colours) > 50
        await page.screenshot(path=str(ARTIFACTS / "report.png"), full_page=True)
        # Everything came from the service itself: the page works with no internet.
        assert all(u.startswith((url, "data:", "blob:")) for u in requested), [
            u for u in requested if not u.startswith(url)
        ]
        assert await page.locator("#residuals .main-svg").count() >= 1
        # Bad ids get a 404 page, not a traceback.
        resp = await page.goto(f"{url}/jobs/0123456789abcdef0123456789abcdef")
        content = await page.content()
        assert resp.status == 404 and "Job not found" in content and "Traceback" not in content


def test_cli_writes_the_same_report(service: tuple[str, dict[str, Any]], sim: Path, tmp_path: Path) -> None:
    url, job = service
    out = tmp_path / "r.html"
    proc = subprocess.run(
        [sys.executable, "-m", "tumblescan", "report", job["id"], "--out", str(out), "--url", url],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert out.read_bytes() == httpx.get(job["artifacts"]["report"]).content
    proc = subprocess.run(
        [sys.executable, "-m", "tumblescan", "report", "f" * 32, "--url", url],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2 and "not found" in proc.stderr
    local = tmp_path / "local.html"
    cmd = [
        sys.executable,
        "-m",
        "tumblescan",
        "estimate",
        str(sim / "tracks.json"),
        "--report",
        str(local),
        "--cloud",
        str(sim / "frames.ply"),
        "--truth",
        str(sim / "truth.json"),
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    page = local.read_text()
    assert f"{job['result']['spin']['rate_deg_s']:.6f}" in page and "precession cone" in page


def test_pages_need_a_key_and_show_only_the_keys_jobs(tmp_path: Path, sim: Path) -> None:
    env = {"TUMBLESCAN_API_KEYS": "alpha,beta"}
    with serve(tmp_path / "data", workers=1, extra_env=env) as url:
        tracks = (sim / "tracks.json").read_bytes()
        ids = {}
        for key in ("alpha", "beta"):
            r = httpx.post(
                f"{url}/v1/jobs/upload", files={"file": ("t.json", tracks)}, headers={"Authorization": f"Bearer {key}"}
            )
            ids[key] = r.json()["id"]
        assert httpx.get(f"{url}/").status_code == 401
        with httpx.Client(base_url=url) as browser:
            r = browser.get("/", params={"api_key": "alpha"})
            assert r.status_code == 200 and ids["alpha"] in r.text and ids["beta"] not in r.text
            # The key is kept in a cookie for the links that follow.
            assert browser.get(f"/jobs/{ids['alpha']}").status_code == 200
            assert browser.get(f"/jobs/{ids['beta']}").status_code == 404


# The summary of a report built in-process from the simulated job, frames and tracks alike.


@pytest.fixture(scope="module")
def frames_outcome(sim: Path) -> Outcome:
    return estimate_frames(sim / "frames.ply", FramesOptions())


@pytest.fixture(scope="module")
def tracks_outcome(sim: Path) -> Outcome:
    return estimate_tracks(sim / "tracks.json", TracksOptions())


def _report(outcome: Outcome, truth: Motion | None) -> str:
    inputs = ReportInputs(
        result=outcome.result,
        tracks=outcome.tracks,
        distorted=outcome.cloud,
        rectified=outcome.rectified,
        truth=truth,
    )
    return build_report(inputs)


def _cell(page: str, field: str) -> tuple[str, str]:
    """The attributes after ``data-field`` and the text of a report's cell."""
    m = re.search(rf"""data-field='{re.escape(field)}'([^>]*)>(.*?)</td>""", page)
    assert m, f"no cell {field}"
    return m.group(1), m.group(2)


def test_frames_report_fit_row_says_the_points_used(frames_outcome: Outcome, sim: Path) -> None:
    r = frames_outcome.result
    assert r.fit.source == "frames" and r.fit.points_used is not None
    _, fit = _cell(_report(frames_outcome, load_truth(sim / "truth.json")), "fit.rms_residual_m")
    assert f"{r.fit.points_used} of {r.fit.observations} points" in fit
    assert "surfel-to-plane" in fit and "tracks" not in fit and "observations" not in fit
    # The words the CLI prints (``fit_text``), lengths in mm rather than m.
    assert fit == fit_text(r.fit, "mm") and fit_text(r.fit).startswith(f"rms {r.fit.rms_residual_m:.3g} m ")


def test_tracks_report_fit_row_keeps_the_tracks_wording(tracks_outcome: Outcome) -> None:
    r = tracks_outcome.result
    _, fit = _cell(_report(tracks_outcome, None), "fit.rms_residual_m")
    assert f"{r.fit.observations} observations, {r.fit.tracks} tracks, {r.fit.frames} frames" in fit
    assert " of " not in fit and r.fit.tracks > 0
    assert fit == fit_text(r.fit, "mm")


@pytest.mark.parametrize("source", ["frames", "tracks"])
def test_centre_sigma_and_error_are_both_in_mm(
    source: str, frames_outcome: Outcome, tracks_outcome: Outcome, sim: Path
) -> None:
    outcome = frames_outcome if source == "frames" else tracks_outcome
    truth = load_truth(sim / "truth.json")
    page = _report(outcome, truth)
    row = re.search(r"<tr><th>centre \(m\)</th>.*?</tr>", page)
    assert row, "no centre row"
    _, sigma, _, error = re.findall(r"<td[^>]*>(.*?)</td>", row.group(0))
    assert sigma.endswith(" mm")
    error_mm = errors_against(outcome.result, truth)["center_m"] * 1000
    assert _cell(page, "error.precession.center_m")[1] == f"{error_mm:.3g} mm" == error
    # Axis errors carry their sigma's unit too.
    assert _cell(page, "error.spin.axis")[1].endswith(" deg")


def test_nutation_error_against_the_truth(frames_outcome: Outcome, sim: Path) -> None:
    r = frames_outcome.result
    truth = load_truth(sim / "truth.json")
    assert r.nutation_angle_deg is not None
    attrs, error = _cell(_report(frames_outcome, truth), "error.nutation_angle_deg")
    assert error == f"{r.nutation_angle_deg - truth.nutation_angle_deg():.3g}" and "title" not in attrs
    assert abs(float(error)) < 1.0
    # A truth without precession has no nutation angle: a dash, and why.
    still = dataclasses.replace(truth, precession_rate_rad_s=0.0)
    attrs, error = _cell(_report(frames_outcome, still), "error.nutation_angle_deg")
    assert error == "&ndash;" and "no precession" in attrs
