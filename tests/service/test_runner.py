"""A store outage during a job costs progress notes, never the job or its result; a shutdown
interrupt puts the job back in the queue, whatever its libraries made of it."""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy.exc import OperationalError

from tumblescan.jobs import queue, runner
from tumblescan.jobs.artifacts import ArtifactStore
from tumblescan.jobs.kind import JobContext, JobOutput
from tumblescan.jobs.runtime import Runtime
from tumblescan.jobs.store import JobStore
from tumblescan.settings import Settings


class FlakyStore(JobStore):
    """A real SQLite store whose named writes fail ``outages[name]`` times before they work."""

    def __init__(self, url: str, outages: dict[str, int]) -> None:
        super().__init__(url)
        self.outages = dict(outages)
        self.calls: dict[str, int] = {}

    def _maybe_down(self, name: str) -> None:
        self.calls[name] = self.calls.get(name, 0) + 1
        if self.outages.get(name, 0) > 0:
            self.outages[name] -= 1
            raise OperationalError("UPDATE jobs", {}, Exception("connection refused"))

    def progress(self, job_id: str, stage: str, fraction: float, attempt: int | None = None) -> None:
        self._maybe_down("progress")
        super().progress(job_id, stage, fraction, attempt)

    def succeed(
        self, job_id: str, result: dict[str, Any], artifacts: dict[str, str], attempt: int | None = None
    ) -> bool:
        self._maybe_down("succeed")
        return super().succeed(job_id, result, artifacts, attempt)

    def fail(
        self,
        job_id: str,
        code: str,
        message: str,
        *,
        from_status: tuple[str, ...] = ("running",),
        attempt: int | None = None,
    ) -> bool:
        self._maybe_down("fail")
        return super().fail(job_id, code, message, from_status=from_status, attempt=attempt)

    def mark_cancelled(self, job_id: str, attempt: int | None = None) -> bool:
        self._maybe_down("mark_cancelled")
        return super().mark_cancelled(job_id, attempt)

    def mark_artifacts_deleted(self, job_id: str) -> None:
        self._maybe_down("mark_artifacts_deleted")
        super().mark_artifacts_deleted(job_id)


class CountingKind:
    """Reports progress a few times, then returns a result (or raises what it is given)."""

    name = "counting"

    def __init__(self, error: Exception | None = None, meanwhile: Callable[[], object] | None = None) -> None:
        self.error, self.meanwhile = error, meanwhile

    def run(self, ctx: JobContext) -> JobOutput:
        for i in range(5):
            ctx.report("counting", i / 5)
            if i == 2 and self.meanwhile is not None:
                self.meanwhile()
        if self.error is not None:
            raise self.error
        return JobOutput(result={"counted": 5})


def setup(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, kind: CountingKind, **outages: int) -> tuple[Runtime, str]:
    monkeypatch.setattr(runner, "get_kind", lambda name: kind)
    monkeypatch.setattr(runner, "PROGRESS_INTERVAL_S", 0.0)  # every report writes
    settings = Settings(data_dir=tmp_path)
    store = FlakyStore(settings.db_url, outages)
    rt = Runtime(settings, store, ArtifactStore(settings.artifacts))
    job = store.create(kind="counting", options={}, input={"data": "input-data.bin"}, owner=None)
    rt.artifacts.job_dir(job.id).mkdir(parents=True)
    rt.artifacts.path(job.id, "input-data.bin").write_bytes(b"uploaded")
    return rt, job.id


def test_a_job_survives_the_store_going_away_during_progress_and_at_its_result(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    rt, job_id = setup(tmp_path, monkeypatch, CountingKind(), progress=3, succeed=2)
    assert runner.run_job(rt, job_id) == "succeeded"
    job = rt.store.get(job_id)
    assert job is not None and job.status == "succeeded" and job.result == {"counted": 5}
    assert rt.store.calls["succeed"] == 3  # type: ignore[attr-defined]


def test_a_failure_is_recorded_once_the_store_is_back(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    rt, job_id = setup(tmp_path, monkeypatch, CountingKind(RuntimeError("boom")), fail=2)
    assert runner.run_job(rt, job_id) == "failed"
    job = rt.store.get(job_id)
    assert job is not None and job.status == "failed" and job.error_code == "internal_error"


def test_a_store_that_stays_down_leaves_the_job_to_the_reaper(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    rt, job_id = setup(tmp_path, monkeypatch, CountingKind(), succeed=1000)
    monkeypatch.setattr(runner, "STORE_PATIENCE_S", 0.0)
    assert runner.run_job(rt, job_id) is None
    job = rt.store.get(job_id)
    assert job is not None and job.status == "running"  # the reaper requeues it when the lease lapses


def test_a_run_superseded_by_a_rerun_stops_without_touching_the_rerun_or_its_files(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    kind = CountingKind()
    rt, job_id = setup(tmp_path, monkeypatch, kind)

    def lease_lost_and_rerun() -> None:  # what the reaper and another worker do while this run is cut off
        assert rt.store.requeue(job_id)
        assert rt.store.claim(job_id, worker="other:1") is not None

    kind.meanwhile = lease_lost_and_rerun
    assert runner.run_job(rt, job_id) is None
    job = rt.store.get(job_id)
    assert job is not None and job.status == "running" and job.attempts == 2 and job.worker == "other:1"
    assert rt.artifacts.path(job_id, "input-data.bin").read_bytes() == b"uploaded"
    # The late run's writes are refused; the rerun's go through.
    assert not rt.store.succeed(job_id, {"late": True}, {}, attempt=1)
    assert rt.store.succeed(job_id, {"counted": 5}, {}, attempt=2)


@pytest.mark.parametrize("down", ["mark_cancelled", "mark_artifacts_deleted"])
def test_a_cancellation_during_an_outage_is_recorded_once_the_store_is_back(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, down: str
) -> None:
    kind = CountingKind()
    rt, job_id = setup(tmp_path, monkeypatch, kind, **{down: 2})
    kind.meanwhile = lambda: rt.store.request_cancel(job_id)
    assert runner.run_job(rt, job_id) == "cancelled"
    job = rt.store.get(job_id)
    assert job is not None and job.status == "cancelled"
    assert not rt.artifacts.job_dir(job_id).exists()


def _cancel_while_never_back(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, down: str
) -> tuple[Runtime, str, str | None]:
    """A job cancelled while it runs, with the store's ``down`` write failing for good; the
    runtime, the job and what ``run_job`` returned."""
    kind = CountingKind()
    rt, job_id = setup(tmp_path, monkeypatch, kind, **{down: 1000})
    monkeypatch.setattr(runner, "STORE_PATIENCE_S", 0.0)
    kind.meanwhile = lambda: rt.store.request_cancel(job_id)
    return rt, job_id, runner.run_job(rt, job_id)


def test_a_cancellation_the_store_never_hears_of_leaves_the_job_to_the_reaper(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    rt, job_id, outcome = _cancel_while_never_back(tmp_path, monkeypatch, "mark_cancelled")
    assert outcome is None  # not an OperationalError out of the worker
    job = rt.store.get(job_id)
    assert job is not None and job.status == "running"
    assert rt.artifacts.path(job_id, "input-data.bin").read_bytes() == b"uploaded"


def test_files_deleted_but_not_marked_so_still_end_the_job_cancelled(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    rt, job_id, outcome = _cancel_while_never_back(tmp_path, monkeypatch, "mark_artifacts_deleted")
    assert outcome == "cancelled"
    job = rt.store.get(job_id)
    assert job is not None and job.status == "cancelled"


class SchemaBuildError(Exception):
    """What pydantic-core raised when the shutdown interrupt reached it building a schema."""


def test_a_job_interrupted_by_shutdown_goes_back_to_the_queue_whatever_its_libraries_raise(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The consumer stops a running job by raising KeyboardInterrupt in it; a library turned that
    # into an error of its own, and the job failed. Noted as a shutdown, it leaves as the
    # interrupt, still running, for huey's signal to put it back in the queue.
    monkeypatch.setattr(runner, "SHUTTING_DOWN", threading.Event())
    kind = CountingKind(SchemaBuildError("Error building 'literal' validator: KeyboardInterrupt"))
    rt, job_id = setup(tmp_path, monkeypatch, kind)
    kind.meanwhile = runner.SHUTTING_DOWN.set
    with pytest.raises(KeyboardInterrupt):
        runner.run_job(rt, job_id)
    job = rt.store.get(job_id)
    assert job is not None and job.status == "running" and job.error_code is None


def test_an_error_caused_by_the_interrupt_is_the_interrupt(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(runner, "SHUTTING_DOWN", threading.Event())
    try:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as interrupt:
            raise RuntimeError("wrapped") from interrupt
    except RuntimeError as wrapped:
        error = wrapped
    rt, job_id = setup(tmp_path, monkeypatch, CountingKind(error))
    with pytest.raises(KeyboardInterrupt):
        runner.run_job(rt, job_id)
    job = rt.store.get(job_id)
    assert job is not None and job.status == "running"


def test_the_workers_shutdown_signal_is_noted_before_hueys_handler_runs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(queue, "SHUTTING_DOWN", threading.Event())
    seen: list[bool] = []

    def hueys(signum: int, frame: object) -> None:  # stands in for huey's: raises in the task
        seen.append(queue.SHUTTING_DOWN.is_set())

    original = signal.signal(signal.SIGTERM, hueys)
    try:
        huey, _ = queue.make_huey(Settings(data_dir=tmp_path))
        for startup_hook in huey._startup.values():  # what each worker process runs as it starts
            startup_hook()
        assert signal.getsignal(signal.SIGTERM) is not hueys  # wrapped by make_huey's startup hook
        queue._note_shutdown_signal()  # a second call wraps nothing more
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.05)
    finally:
        signal.signal(signal.SIGTERM, original)
    assert seen == [True]


def _refusal(model: type[Any], doc: dict[str, Any]) -> Exception:
    try:
        model.model_validate(doc)
    except ValueError as exc:
        return exc
    raise AssertionError(f"{model.__name__} took {doc}")


def _options_refusal() -> Exception:
    from tumblescan.bearings.options import EstimateOptions

    return _refusal(EstimateOptions, {"method": "paper", "gate_chi2": 1.0})


def _result_refusal() -> Exception:
    from pydantic import BaseModel

    class Result(BaseModel):
        n: int

    return _refusal(Result, {"n": "many"})


@pytest.mark.parametrize(
    ("refusal", "code", "message"),
    [
        # A job queued before an upgrade made an option stricter: the caller's to change.
        (_options_refusal, "invalid_options", "options.gate_chi2: "),
        # Any other model failing its validation is still our fault.
        (_result_refusal, "internal_error", "ValidationError: "),
    ],
)
def test_a_validation_error_is_the_callers_only_when_it_is_of_the_options(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, refusal: Callable[[], Exception], code: str, message: str
) -> None:
    rt, job_id = setup(tmp_path, monkeypatch, CountingKind(refusal()))
    assert runner.run_job(rt, job_id) == "failed"
    job = rt.store.get(job_id)
    assert job is not None and job.error_code == code
    assert job.error_message is not None and job.error_message.startswith(message)
