"""Load: 500 small tracks jobs from 50 concurrent async clients, against the embedded defaults
and against the scale-out mode (API + 2 worker processes on Redis and PostgreSQL).

Checks that every job succeeds and that every result equals a direct library call with the
same seed; prints throughput, p50/p99 submit latency, p50/p99 time to result, and the p99 of
a health check polled throughout (requirement: under 100 ms while the workers are saturated).

Usage: python -m bench.service.load [--jobs 500] [--clients 50] [--modes embedded,scaleout]
"""

from __future__ import annotations

import argparse
import asyncio
import multiprocessing
import sys
import tempfile
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import httpx
import numpy as np

from tumblescan import EstimateOptions, estimate_motion, tracks_from_json, tracks_to_json
from tumblescan_client import AsyncClient

from ..common import machine, scenario, table

VARIANTS = 10  # distinct (tracks, seed) inputs, each checked against the library


async def run_load(url: str, inputs: list[dict[str, Any]], jobs: int, clients: int) -> dict[str, Any]:
    submit_s: list[float] = []
    result_s: list[float] = []
    results: dict[int, dict[str, Any]] = {}
    # The health prober runs in its own process so the clients' event loop does not delay it.
    ctx = multiprocessing.get_context("spawn")
    stop_probe, health_q = ctx.Event(), ctx.Queue()
    prober = ctx.Process(target=probe_health, args=(url, stop_probe, health_q))
    prober.start()

    async def one_client(k: int, client: AsyncClient) -> None:
        for i in range(k, jobs, clients):
            t0 = time.perf_counter()
            job = await client.jobs.create(tracks=inputs[i % VARIANTS], options={"seed": i % VARIANTS})
            submit_s.append(time.perf_counter() - t0)
            finished = await client.jobs.wait(job.id, timeout=1200)
            result_s.append(time.perf_counter() - t0)
            assert finished.status == "succeeded", finished
            results[i] = finished.result or {}

    t_start = time.perf_counter()
    async with AsyncClient(url, max_retries=5) as client:
        await asyncio.gather(*(one_client(k, client) for k in range(clients)))
    total = time.perf_counter() - t_start
    stop_probe.set()
    health_s = health_q.get(timeout=60)
    prober.join(timeout=30)
    return {
        "total": total,
        "submit": np.array(submit_s),
        "result": np.array(result_s),
        "health": np.array(health_s),
        "results": results,
    }


def probe_health(url: str, stop: Any, out: Any) -> None:
    """GET /healthz every 50 ms until stopped; puts the latencies (s) on ``out``."""
    latencies = []
    with httpx.Client(base_url=url, timeout=10) as http:
        while not stop.is_set():
            t = time.perf_counter()
            assert http.get("/healthz").status_code == 200
            latencies.append(time.perf_counter() - t)
            time.sleep(0.05)
    out.put(latencies)


def check_against_library(inputs: list[dict[str, Any]], results: dict[int, dict[str, Any]]) -> int:
    """Every service result equals the library's with the same tracks and seed (timing aside)."""
    direct = [
        estimate_motion(tracks_from_json(inputs[v]), EstimateOptions(seed=v)).model_dump(mode="json")
        for v in range(VARIANTS)
    ]
    mismatches = 0
    for i, got in results.items():
        want = direct[i % VARIANTS]
        for key in (
            "model",
            "reference_time_s",
            "spin",
            "precession",
            "nutation_angle_deg",
            "uncertainty",
            "fit",
            "validation",
            "warnings",
        ):
            mismatches += got[key] != want[key]
    return mismatches


def embedded(tmp: Path, stack: ExitStack) -> str:
    from tests.live import serve

    return stack.enter_context(serve(tmp / "embedded", workers=2))


def scaleout(tmp: Path, stack: ExitStack) -> str:
    from tests.infra import ensure_redis, postgres_database, scaleout_env
    from tests.live import serve, spawn, stop, wait_ready

    ensure_redis()
    env = scaleout_env(stack.enter_context(postgres_database()), tmp / "shared")
    workers = [
        spawn(["worker", "--workers", "1"], {**env, "TUMBLESCAN_DATA_DIR": str(tmp / f"w{i}")}, tmp / f"w{i}.log")
        for i in range(2)
    ]
    for w in workers:
        stack.callback(stop, w)
    url = stack.enter_context(serve(tmp / "api", extra_env=env, args=["--no-workers"]))
    wait_ready(url, workers[0], tmp / "w0.log")
    return url


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--jobs", type=int, default=500)
    ap.add_argument("--clients", type=int, default=50)
    ap.add_argument("--modes", default="embedded,scaleout")
    args = ap.parse_args()
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    print(f"machine: {machine()}")
    inputs = [tracks_to_json(scenario(seed, noise=True)[1]) for seed in range(VARIANTS)]
    rows = []
    for mode in args.modes.split(","):
        with tempfile.TemporaryDirectory() as tmp, ExitStack() as stack:
            url = {"embedded": embedded, "scaleout": scaleout}[mode](Path(tmp), stack)
            out = asyncio.run(run_load(url, inputs, args.jobs, args.clients))
        bad = check_against_library(inputs, out["results"])
        ms = 1000
        rows.append(
            [
                mode,
                f"{len(out['results'])}/{args.jobs}",
                "all equal" if bad == 0 else f"{bad} differ",
                args.jobs / out["total"],
                float(np.percentile(out["submit"], 50) * ms),
                float(np.percentile(out["submit"], 99) * ms),
                float(np.percentile(out["result"], 50)),
                float(np.percentile(out["result"], 99)),
                float(np.percentile(out["health"], 99) * ms),
            ]
        )
    header = [
        "mode",
        "succeeded",
        "vs library",
        "jobs/s",
        "submit p50 ms",
        "submit p99 ms",
        "result p50 s",
        "result p99 s",
        "healthz p99 ms",
    ]
    print(table(rows, header))


if __name__ == "__main__":
    main()
