"""``tumblescan demo``: the service on its embedded defaults, one simulated job end to end."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Annotated

import typer

from .remote import ProgressBar


def demo(
    out: Annotated[Path, typer.Option(help="where the demo writes its files")] = Path("demo-output"),
    seed: Annotated[int, typer.Option(min=0)] = 7,
    port: Annotated[int, typer.Option(help="0: any free port")] = 0,
    keep_serving: Annotated[bool, typer.Option(help="keep the service running afterwards (Ctrl-C stops it)")] = False,
) -> None:
    """Start the service on the embedded defaults, simulate the raw frames a line-scan lidar
    records of a tumbling satellite, submit them (motion from dense frames: no tracks, no
    features), wait with a progress bar, print the estimate next to the truth and write the
    rectified cloud and the report."""
    import numpy as np

    from tumblescan_client import Client

    from ..io.ply import TimedCloud, read_ply, write_ply
    from ..linescan.report_text import comparison_table
    from ..linescan.result import MotionResult
    from ..linescan.simulate import Scene, random_motion, simulate_frames
    from ..linescan.truth import motion_to_json

    out.mkdir(parents=True, exist_ok=True)
    port = port or _free_port()
    url = f"http://127.0.0.1:{port}"
    typer.echo(f"starting the service at {url} (data in {out / 'data'})...")
    server = _start_server(port, out / "data", out / "service.log")
    try:
        _wait_ready(url, server, timeout_s=120)
        rng = np.random.default_rng(seed)
        motion = random_motion(rng)
        scene = Scene()
        typer.echo(
            f"simulating {scene.frames} raw frames of a 14.4 m satellite at 50 m (Table 1 scanner and noise, "
            f"seed {seed})..."
        )
        cloud = simulate_frames(motion, scene, seed=seed)
        write_ply(out / "frames.ply", TimedCloud(cloud.xyz_m, cloud.t_s, {"frame": cloud.frame, "line": cloud.line}))
        typer.echo(f"wrote {out / 'frames.ply'}: {len(cloud.t_s):,} returns, each with its own time")
        (out / "truth.json").write_text(json.dumps({"motion": motion_to_json(motion), "seed": seed}, indent=2))
        with Client(url) as client:
            files = {"file": out / "frames.ply", "truth": out / "truth.json"}
            job = client.jobs.upload("linescan-motion", files=files, options={"seed": seed})
            typer.echo(f"submitted job {job.id}")
            job = client.jobs.wait(job.id, timeout=600, on_progress=ProgressBar())
            typer.echo("")
            if job.status != "succeeded" or job.result is None:
                typer.echo(f"error: job {job.status}: {job.error}", err=True)
                raise typer.Exit(1)
            result = MotionResult.model_validate(job.result)
            client.jobs.download_cloud(job.id, out / "rectified.ply")
            client.jobs.download_report(job.id, out / "report.html")
        (out / "result.json").write_text(result.model_dump_json(indent=2))
        typer.echo(comparison_table(result, motion))
        rect = read_ply(out / "rectified.ply")
        T = result.reference_time_s
        true_rect = motion.position(cloud.reference_m, np.full(len(cloud.t_s), T))
        err_mm = 1000 * float(np.linalg.norm(rect.xyz_m - true_rect, axis=1).mean())
        verdict = "passed" if result.validation.passed else "FAILED"
        typer.echo(f"\nvalidation {verdict}; solver {result.solver.path}, {result.solver.elapsed_s * 1000:.0f} ms")
        typer.echo(
            f"rectified {len(rect)} points to t={T:.4f} s: mean distance to the true undistorted cloud "
            f"{err_mm:.1f} mm (2 cm sensor noise included)"
        )
        typer.echo(f"wrote {out / 'rectified.ply'}, {out / 'result.json'} and {out / 'report.html'}")
        typer.echo(f"report: {url}/jobs/{job.id} (written to {out / 'report.html'})")
        if keep_serving:
            typer.echo(f"serving at {url} (job list at {url}/); Ctrl-C stops")
            server.wait()
        else:
            typer.echo("the service stops with the demo; --keep-serving keeps it up to browse the report there")
    finally:
        server.send_signal(signal.SIGINT)
        try:
            server.wait(timeout=30)
        except subprocess.TimeoutExpired:
            server.kill()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _start_server(port: int, data_dir: Path, log_path: Path) -> subprocess.Popen[bytes]:
    env = dict(
        os.environ, TUMBLESCAN_DATA_DIR=str(data_dir.resolve()), TUMBLESCAN_PORT=str(port), TUMBLESCAN_HOST="127.0.0.1"
    )
    log = open(log_path, "ab")  # noqa: SIM115 (the server process owns it)
    return subprocess.Popen(
        [sys.executable, "-m", "tumblescan", "serve"], env=env, stdout=log, stderr=subprocess.STDOUT
    )


def _wait_ready(url: str, server: subprocess.Popen[bytes], timeout_s: float) -> None:
    import httpx

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if server.poll() is not None:
            raise RuntimeError(f"the service exited with code {server.returncode}; see its log")
        try:
            if httpx.get(f"{url}/readyz", timeout=2).status_code == 200:
                return
        except httpx.TransportError:
            pass
        time.sleep(0.2)
    raise RuntimeError(f"the service at {url} was not ready within {timeout_s} s")
