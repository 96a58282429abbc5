"""Real service processes for tests: ``tumblescan serve`` / ``tumblescan worker`` on free ports."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx

FINAL = ("succeeded", "failed", "cancelled")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def spawn(args: list[str], env: dict[str, str], log: Path) -> subprocess.Popen[bytes]:
    fh = open(log, "ab")  # noqa: SIM115 (owned by the child)
    return subprocess.Popen(
        [sys.executable, "-m", "tumblescan", *args], env={**os.environ, **env}, stdout=fh, stderr=subprocess.STDOUT
    )


def wait_ready(
    url: str, proc: subprocess.Popen[bytes], log: Path, timeout_s: float = 90.0, path: str = "/readyz"
) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"service exited with {proc.returncode}:\n{log.read_text()[-3000:]}")
        try:
            if httpx.get(url + path, timeout=2).status_code == 200:
                return
        except httpx.TransportError:
            pass
        time.sleep(0.1)
    raise RuntimeError(f"service not ready in {timeout_s} s:\n{log.read_text()[-3000:]}")


def stop(proc: subprocess.Popen[bytes], sig: int = signal.SIGINT, timeout_s: float = 30.0) -> None:
    if proc.poll() is None:
        proc.send_signal(sig)
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@contextmanager
def serve(
    data_dir: Path, *, workers: int = 2, extra_env: dict[str, str] | None = None, args: list[str] | None = None
) -> Iterator[str]:
    """``tumblescan serve`` with embedded workers; yields its base URL."""
    port = free_port()
    env = {"TUMBLESCAN_DATA_DIR": str(data_dir), "TUMBLESCAN_PORT": str(port), "TUMBLESCAN_WORKERS": str(workers)}
    env.update(extra_env or {})
    log = data_dir.parent / f"{data_dir.name}-serve.log"
    data_dir.mkdir(parents=True, exist_ok=True)
    proc = spawn(["serve", *(args or [])], env, log)
    url = f"http://127.0.0.1:{port}"
    try:
        wait_ready(url, proc, log, path="/healthz" if args and "--no-workers" in args else "/readyz")
        yield url
    finally:
        stop(proc)


def wait_job(
    http: httpx.Client, job_id: str, *, statuses: tuple[str, ...] = FINAL, timeout_s: float = 120
) -> dict[str, Any]:
    """Poll a job until its status is one of ``statuses``; fail the test after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while True:
        job: dict[str, Any] = http.get(f"/v1/jobs/{job_id}").json()
        if job["status"] in statuses:
            return job
        assert time.monotonic() < deadline, f"job {job_id} not {statuses} within {timeout_s} s: {job}"
        time.sleep(0.05)
