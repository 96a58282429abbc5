"""``numerics.parallel``: calls spread over the process's share of the cores, in order, and run in
turn when the share is one core."""

from __future__ import annotations

import multiprocessing
import os
from functools import partial

import pytest

from tumblescan.numerics.parallel import cores, parallel_map


def _power(x: int, *, p: int) -> tuple[int, int]:
    return x**p, os.getpid()


def test_cores_follow_the_thread_budget(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    assert cores() == 3
    monkeypatch.delenv("OMP_NUM_THREADS")
    assert cores() == len(os.sched_getaffinity(0))


def test_one_core_runs_the_calls_here(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    out = parallel_map(partial(_power, p=2), list(range(5)))
    assert [v for v, _ in out] == [0, 1, 4, 9, 16]
    assert {pid for _, pid in out} == {os.getpid()}


def test_two_cores_run_the_calls_in_other_processes_in_order(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    out = parallel_map(partial(_power, p=3), list(range(12)))
    assert [v for v, _ in out] == [x**3 for x in range(12)]
    assert os.getpid() not in {pid for _, pid in out}


def _pids_in_a_daemon(out: multiprocessing.Queue) -> None:
    os.environ["OMP_NUM_THREADS"] = "2"
    out.put((os.getpid(), parallel_map(partial(_power, p=2), [1, 2, 3])))


def test_a_daemonic_process_runs_the_calls_itself() -> None:
    """The service's queue workers are daemonic, and may not start processes."""
    ctx = multiprocessing.get_context("fork")
    out = ctx.Queue()
    proc = ctx.Process(target=_pids_in_a_daemon, args=(out,), daemon=True)
    proc.start()
    pid, results = out.get(timeout=60)
    proc.join(timeout=60)
    assert [v for v, _ in results] == [1, 4, 9]
    assert {p for _, p in results} == {pid}


def test_an_error_in_a_call_reaches_the_caller(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    with pytest.raises(ZeroDivisionError):
        parallel_map(partial(_power, p=-1), [1, 0, 2])
