"""Run one job of every registered kind against a running service; the job half of
scripts/container-smoke, which pipes this file into ``python -`` inside the container so that
the image's own ``simulate`` commands make the data and its own Python submits it.

Environment: SMOKE_URL (default http://127.0.0.1:8000), SMOKE_API_KEY, SMOKE_TIMEOUT_S (per job).
Exit status 0 only when every registered kind has a recipe and each of its jobs succeeded with
all its artifacts (the report included) downloadable. Standard library and httpx only.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx


@dataclass(frozen=True)
class Job:
    """One job of a kind: the upload parts (field -> file made by the kind's simulate, or a glob
    of files) and options."""

    label: str
    parts: dict[str, str]
    options: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Recipe:
    """How to make a kind's input with the image's own CLI (command lines, split on spaces, that
    write into the directory ``{out}`` names) and which jobs to submit from it."""

    simulate: tuple[str, ...]
    jobs: list[Job]


# One entry per registered kind. A kind that GET /v1/kinds lists without an entry here fails
# the smoke test: add its recipe when registering it (small inputs: this runs in CI).
RECIPES: dict[str, Recipe] = {
    "linescan-motion": Recipe(
        simulate=("tumblescan linescan-motion simulate --out {out} --lines 128 --pixels 128 --seed 3",),
        jobs=[
            Job("tracks", {"file": "tracks.json", "truth": "truth.json"}),
            Job("dense frames", {"file": "frames.ply", "truth": "truth.json"}),
        ],
    ),
    "panel-axis": Recipe(
        simulate=("tumblescan panel-axis simulate --out {out} --seed 3 --width-px 512 --height-px 384",),
        jobs=[Job("near range", {"meta": "meta.json", "image": "image.png"})],
    ),
    "marker-pose-graph": Recipe(
        simulate=(
            "tumblescan marker-pose-graph simulate --out {out} --seed 3 --frames 200",
            "tumblescan marker-pose-graph simulate --out {out} --seed 3 --frames 100 --level B",
            "tumblescan marker-pose-graph simulate --out {out} --seed 3 --frames 6 --level C",
        ),
        jobs=[
            Job("level A markers", {"markers": "markers.json"}),
            Job("level B tags", {"tags": "tags.json"}),
            Job("level C images", {"images": "images.zip"}),
        ],
    ),
    "spin-from-images": Recipe(
        simulate=("tumblescan spin-from-images simulate --out {out} --seed 3",),
        jobs=[Job("image sequence", {"meta": "meta.json", "frames": "frames/*.png"})],
    ),
    "bearings": Recipe(
        simulate=("tumblescan bearings simulate --out {out} --scene leo --targets 5 --clutter 0.2 --seed 3",),
        jobs=[
            Job("LEO (ECEF)", {"input": "input.json"}),
            Job("paper method", {"input": "input.json"}, {"method": "paper"}),
        ],
    ),
}
# Before GET /v1/kinds existed the service ran this kind only.
KINDS_BEFORE_DISCOVERY = ["linescan-motion"]


def main() -> int:
    url = os.environ.get("SMOKE_URL", "http://127.0.0.1:8000").rstrip("/")
    key = os.environ.get("SMOKE_API_KEY")
    timeout_s = float(os.environ.get("SMOKE_TIMEOUT_S", "600"))
    headers = {"Authorization": f"Bearer {key}"} if key else {}
    with httpx.Client(base_url=url, headers=headers, timeout=60) as http:
        kinds = registered_kinds(http)
        missing = [k for k in kinds if k not in RECIPES]
        if missing:
            print(
                f"FAIL: no smoke recipe for registered kind(s) {', '.join(missing)}: "
                "add one to RECIPES in scripts/container_smoke_jobs.py",
                file=sys.stderr,
            )
            return 1
        rows: list[tuple[str, str, str, float, float]] = []
        failures = 0
        with tempfile.TemporaryDirectory(prefix="smoke-") as tmp:
            for kind in kinds:
                recipe = RECIPES[kind]
                out = Path(tmp) / kind
                t0 = time.monotonic()
                if not simulate(kind, recipe, out):
                    failures += len(recipe.jobs)
                    continue
                sim_s = time.monotonic() - t0
                for job in recipe.jobs:
                    status, seconds = run_job(http, kind, job, out, timeout_s)
                    failures += status != "succeeded"
                    rows.append((kind, job.label, status, sim_s, seconds))
    print(f"{'kind':<22} {'input':<16} {'status':<10} {'simulate s':>10} {'job s':>8}")
    for kind, label, status, sim_s, seconds in rows:
        print(f"{kind:<22} {label:<16} {status:<10} {sim_s:>10.1f} {seconds:>8.1f}")
    if failures:
        print(f"FAIL: {failures} job(s) did not succeed", file=sys.stderr)
        return 1
    print(f"all {len(rows)} job(s) of {len(kinds)} kind(s) succeeded")
    return 0


def simulate(kind: str, recipe: Recipe, out: Path) -> bool:
    """Run the recipe's simulate command(s); False (the failure printed) if one fails."""
    for command in recipe.simulate:
        cmd = [arg.replace("{out}", str(out)) for arg in command.split()]
        sim = subprocess.run(cmd, capture_output=True, text=True)
        if sim.returncode != 0:
            print(f"FAIL: {kind}: {' '.join(cmd)} exited {sim.returncode}:\n{sim.stderr}", file=sys.stderr)
            return False
    return True


def registered_kinds(http: httpx.Client) -> list[str]:
    """The kinds the service runs (GET /v1/kinds), or the one kind of versions before it."""
    r = http.get("/v1/kinds")
    if r.status_code == 404:
        print(f"GET /v1/kinds is not served: assuming {', '.join(KINDS_BEFORE_DISCOVERY)}")
        return list(KINDS_BEFORE_DISCOVERY)
    r.raise_for_status()
    kinds = [k["name"] for k in r.json()]
    print(f"registered kinds: {', '.join(kinds)}")
    return kinds


def run_job(http: httpx.Client, kind: str, job: Job, data: Path, timeout_s: float) -> tuple[str, float]:
    """Upload, wait, fetch every artifact; the final status (or why it failed) and seconds taken."""
    t0 = time.monotonic()
    # A part names one file, or a glob for a part that takes several (an image sequence).
    handles = [(name, path.open("rb")) for name, pattern in job.parts.items() for path in sorted(data.glob(pattern))]
    try:
        files = [(name, (Path(fh.name).name, fh)) for name, fh in handles]
        r = http.post("/v1/jobs/upload", data={"kind": kind, "options": json.dumps(job.options)}, files=files)
    finally:
        for _, fh in handles:
            fh.close()
    if r.status_code != 202:
        print(f"FAIL: {kind} {job.label}: upload answered {r.status_code}: {r.text[:500]}", file=sys.stderr)
        return f"http {r.status_code}", time.monotonic() - t0
    job_id = r.json()["id"]
    delay = 0.2
    while True:
        body = http.get(f"/v1/jobs/{job_id}").raise_for_status().json()
        if body["status"] in ("succeeded", "failed", "cancelled"):
            break
        if time.monotonic() - t0 > timeout_s:
            print(
                f"FAIL: {kind} {job.label}: job {job_id} still {body['status']} after {timeout_s:.0f} s",
                file=sys.stderr,
            )
            return "timeout", time.monotonic() - t0
        time.sleep(delay)
        delay = min(2.0, delay * 1.5)
    seconds = time.monotonic() - t0
    if body["status"] != "succeeded":
        print(f"FAIL: {kind} {job.label}: job {job_id} {body['status']}: {body.get('error')}", file=sys.stderr)
        return body["status"], seconds
    if not body.get("result"):
        print(f"FAIL: {kind} {job.label}: job {job_id} succeeded without a result", file=sys.stderr)
        return "no result", seconds
    links = [link for link in (body.get("artifacts") or {}).values() if isinstance(link, str)]
    for link in links:
        got = http.get(link)
        if got.status_code != 200 or not got.content:
            print(
                f"FAIL: {kind} {job.label}: {link} answered {got.status_code} ({len(got.content)} bytes)",
                file=sys.stderr,
            )
            return "artifact", seconds
    if not any(link.endswith("/report") for link in links):
        print(f"FAIL: {kind} {job.label}: job {job_id} succeeded without a report link", file=sys.stderr)
        return "no report", seconds
    return "succeeded", seconds


if __name__ == "__main__":
    sys.exit(main())
