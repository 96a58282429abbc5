"""The huey queue: SQLite in the data directory by default, Redis when configured. Tasks
carry only a job id; the job store is the source of truth, so a task that finds its job no
longer queued does nothing, and enqueuing a job twice is harmless."""

from __future__ import annotations

import logging
import signal
import threading
from types import FrameType
from typing import Any

from huey import Huey, RedisHuey, SqliteHuey
from huey.signals import SIGNAL_INTERRUPTED

from ..settings import Settings
from .runner import SHUTTING_DOWN, run_job
from .runtime import get_runtime

log = logging.getLogger("tumblescan.queue")
TASK_NAME = "tumblescan.run_job"


def make_huey(settings: Settings) -> tuple[Huey, Any]:
    """The queue and its single task (``task(job_id)`` enqueues)."""
    if settings.redis_url:
        huey: Huey = RedisHuey(settings.queue_name, url=settings.redis_url, results=False, blocking=True)
    else:
        settings.data_dir.mkdir(parents=True, exist_ok=True)
        huey = SqliteHuey(settings.queue_name, filename=str(settings.data_dir / "queue.db"), results=False)

    @huey.task(name=TASK_NAME)
    def execute(job_id: str) -> None:
        run_job(get_runtime(settings), job_id)

    # Once per worker process, after huey has set its interrupt handler there.
    huey.on_startup()(_note_shutdown_signal)

    @huey.signal(SIGNAL_INTERRUPTED)
    def interrupted(signal: str, task: Any, *args: Any, **kwargs: Any) -> None:
        # The consumer is shutting down mid-job: put the job back for the next start.
        job_id = task.args[0] if task.args else None
        if job_id and get_runtime(settings).store.requeue(job_id, count_attempt=False):
            execute(job_id)
            log.info("job %s interrupted by shutdown and re-queued", job_id)

    return huey, execute


def _note_shutdown_signal() -> None:
    """In a huey worker process, have the consumer's interrupt (SIGTERM, whose handler huey set
    to raise KeyboardInterrupt in the running task) set :data:`.runner.SHUTTING_DOWN` first, so
    that a job whose libraries turn the interrupt into another error still goes back to the
    queue. Elsewhere (no handler of huey's, or not the main thread) nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        return
    previous = signal.getsignal(signal.SIGTERM)
    if not callable(previous) or getattr(previous, "notes_shutdown", False):
        return

    def noted(signum: int, frame: FrameType | None) -> None:
        SHUTTING_DOWN.set()
        previous(signum, frame)

    noted.notes_shutdown = True  # type: ignore[attr-defined]
    signal.signal(signal.SIGTERM, noted)
