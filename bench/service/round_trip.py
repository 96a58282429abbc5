"""Service figures on the embedded defaults (one ``tumblescan serve``, SQLite store and queue,
one worker process per core): round trip of one small tracks job (submit to result, one at a
time) and the throughput of 100 small jobs submitted at once by an async client.

Usage: python -m bench.service.round_trip [--round-trips 30] [--jobs 100]
"""

from __future__ import annotations

import argparse
import asyncio
import tempfile
import time
from pathlib import Path

import numpy as np

from tumblescan import tracks_to_json
from tumblescan_client import AsyncClient, Client

from ..common import machine, out_dir, scenario, table


def round_trips(url: str, tracks: list[dict], n: int) -> np.ndarray:
    out = []
    with Client(url) as client:
        for i in range(n):
            t = time.perf_counter()
            job = client.jobs.create(tracks=tracks[i % len(tracks)])
            client.jobs.result(job.id, timeout=120)
            out.append(time.perf_counter() - t)
    return np.array(out)


async def throughput(url: str, tracks: list[dict], n: int) -> tuple[float, np.ndarray]:
    async with AsyncClient(url) as client:
        t0 = time.perf_counter()
        jobs = await asyncio.gather(
            *(client.jobs.create(tracks=tracks[i % len(tracks)], options={"seed": i}) for i in range(n))
        )
        done = await asyncio.gather(*(client.jobs.wait(j.id, timeout=600) for j in jobs))
        total = time.perf_counter() - t0
    assert all(j.status == "succeeded" for j in done), [j.status for j in done]
    run_s = np.array([(j.finished_at - j.started_at).total_seconds() for j in done])  # type: ignore[operator]
    return total, run_s


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--round-trips", type=int, default=30)
    ap.add_argument("--jobs", type=int, default=100)
    args = ap.parse_args()
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from tests.live import serve

    print(f"machine: {machine()}")
    tracks = [tracks_to_json(scenario(seed, noise=True)[1]) for seed in range(10)]
    with tempfile.TemporaryDirectory() as tmp, serve(Path(tmp) / "data") as url:
        round_trips(url, tracks, 3)  # warm the workers (imports, first SQLite pages)
        rt = round_trips(url, tracks, args.round_trips)
        total, run_s = asyncio.run(throughput(url, tracks, args.jobs))
    rows = [
        ["round trip, one job at a time (ms)", float(np.median(rt) * 1000), float(np.percentile(rt, 90) * 1000)],
        [f"{args.jobs} jobs at once: total (s)", total, "-"],
        [
            f"{args.jobs} jobs at once: run time per job (ms)",
            float(np.median(run_s) * 1000),
            float(np.percentile(run_s, 90) * 1000),
        ],
    ]
    print(table(rows, ["measure", "median / value", "p90"]))
    print(f"throughput: {args.jobs / total:.1f} jobs/s")
    (out_dir() / "service.txt").write_text(
        f"round trip median {np.median(rt) * 1000:.1f} ms; throughput {args.jobs / total:.1f} jobs/s\n"
    )


if __name__ == "__main__":
    main()
