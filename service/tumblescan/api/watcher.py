"""Long-poll support: one task per API process checks every job someone is waiting on with a
single query per tick and wakes the waiters whose job changed, so a change is seen within a
tick however many clients wait, at the cost of one query per tick."""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections import defaultdict

from fastapi.concurrency import run_in_threadpool

from ..jobs.store import JobStore

log = logging.getLogger("tumblescan.api")
Snapshot = tuple[str, str, float]


class JobWatcher:
    def __init__(self, store: JobStore, tick_s: float = 0.01) -> None:
        self.store, self.tick_s = store, tick_s
        self._waiters: dict[str, list[tuple[Snapshot, asyncio.Future[None]]]] = defaultdict(list)
        self._task: asyncio.Task[None] | None = None

    async def wait_for_change(self, job_id: str, seen: Snapshot, timeout_s: float) -> None:
        """Return when the job's (status, stage, progress) differs from ``seen``, or after ``timeout_s``."""
        future: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        entry = (seen, future)
        self._waiters[job_id].append(entry)
        try:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(future, timeout_s)
        finally:
            waiting = self._waiters.get(job_id, [])
            if entry in waiting:
                waiting.remove(entry)
            if not waiting:
                self._waiters.pop(job_id, None)

    def start(self) -> None:
        self._task = asyncio.get_running_loop().create_task(self._run())

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task

    async def _run(self) -> None:
        while True:
            await asyncio.sleep(self.tick_s)
            if not self._waiters:
                continue
            try:
                now = await run_in_threadpool(self.store.snapshots, list(self._waiters))
            except Exception:  # the store is down: waiters time out and the client retries
                log.warning("job watcher could not read the store", exc_info=True)
                await asyncio.sleep(1.0)
                continue
            for job_id, entries in list(self._waiters.items()):
                current = now.get(job_id)
                for seen, future in entries:
                    if current != seen and not future.done():
                        future.set_result(None)
