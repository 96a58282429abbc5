"""``tumblescan serve``: a setting it cannot use stops it at once, in one line with exit 2."""

from __future__ import annotations

import os
import socket
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tumblescan.cli import app

runner = CliRunner()


def test_a_port_out_of_range_or_a_bad_setting_is_one_line(tmp_path: Path) -> None:
    # It was a pydantic traceback with exit 1.
    r = runner.invoke(app, ["serve", "--port", "99999", "--no-workers", "--data-dir", str(tmp_path)])
    assert r.exit_code == 2 and r.output.count("\n") == 1, r.output
    assert "setting port (--port or TUMBLESCAN_PORT)" in r.output
    r = runner.invoke(app, ["serve", "--no-workers", "--data-dir", str(tmp_path)], env={"TUMBLESCAN_WORKERS": "abc"})
    assert r.exit_code == 2 and "TUMBLESCAN_WORKERS" in r.output, r.output


def test_a_port_in_use_is_one_line_before_anything_starts(tmp_path: Path) -> None:
    # It was uvicorn's three log lines and exit 3, after the app's start-up.
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        r = runner.invoke(app, ["serve", "--port", str(port), "--no-workers", "--data-dir", str(tmp_path)])
    assert r.exit_code == 2 and r.output.count("\n") == 1, r.output
    assert f"cannot listen on 127.0.0.1:{port}" in r.output and "in use" in r.output


def test_each_worker_gets_its_share_of_the_cores_unless_the_environment_says(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from tumblescan.cli.service import THREAD_POOL_VARS, share_cores

    for var in THREAD_POOL_VARS:
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setattr("os.cpu_count", lambda: 8)
    share_cores(3)
    assert [os.environ[v] for v in THREAD_POOL_VARS] == ["2", "2", "2"]
    monkeypatch.setenv("OMP_NUM_THREADS", "5")
    monkeypatch.delenv("MKL_NUM_THREADS")
    share_cores(16)  # more workers than cores: one thread each, a user's own setting kept
    assert [os.environ[v] for v in THREAD_POOL_VARS] == ["5", "2", "1"]
