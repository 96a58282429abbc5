"""The FastAPI application. Its lifespan builds the job service, starts the reaper and, in
the embedded mode, the huey consumer as a child process (``tumblescan worker``)."""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI

from ..api import errors
from ..jobs.queue import make_huey
from ..jobs.runtime import get_runtime
from ..jobs.service import JobService, Reaper
from ..settings import Settings, get_settings
from .deps import key_id
from .limits import BodyLimit
from .routes import health, jobs, kinds, pages
from .watcher import JobWatcher

log = logging.getLogger("tumblescan.api")


def worker_env(settings: Settings) -> dict[str, str]:
    """Environment for worker processes: the same settings (the worker command sizes their
    BLAS/OpenMP thread pools)."""
    env = dict(os.environ)
    env.update(
        {
            "TUMBLESCAN_DATA_DIR": str(settings.data_dir.resolve()),
            "TUMBLESCAN_ARTIFACT_DIR": str(settings.artifacts.resolve()),
            "TUMBLESCAN_DATABASE_URL": settings.db_url,
        }
    )
    env["TUMBLESCAN_QUEUE_NAME"] = settings.queue_name
    if settings.redis_url:
        env["TUMBLESCAN_REDIS_URL"] = settings.redis_url
    return env


def start_workers(settings: Settings, count: int) -> subprocess.Popen[bytes]:
    cmd = [sys.executable, "-m", "tumblescan", "worker", "--workers", str(count)]
    return subprocess.Popen(cmd, env=worker_env(settings), preexec_fn=_die_with_parent)


def _die_with_parent() -> None:
    """Linux: the consumer gets SIGTERM if ``serve`` dies without stopping it (SIGKILL, crash),
    so no orphaned workers keep taking jobs."""
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        pr_set_pdeathsig = 1
        libc.prctl(pr_set_pdeathsig, signal.SIGTERM)
    except OSError:
        pass


def create_app(settings: Settings | None = None, *, embedded_workers: int = 0) -> FastAPI:
    """The API; ``embedded_workers > 0`` starts that many worker processes with it."""
    s = settings or get_settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        rt = get_runtime(s)
        huey, task = make_huey(s)
        service = JobService(rt, task, huey.pending_count)
        app.state.service, app.state.settings = service, s
        # Keys are kept only as hashes; the settings object holds them as secrets (never logged).
        app.state.key_hashes = [key_id(k.get_secret_value()) for k in s.api_keys]
        app.state.admin_hashes = [key_id(k.get_secret_value()) for k in s.admin_keys]
        reaper = Reaper(service, s.reaper_interval_s)
        reaper.start()
        app.state.watcher = JobWatcher(rt.store)
        app.state.watcher.start()
        consumer = start_workers(s, embedded_workers) if embedded_workers > 0 else None
        try:
            yield
        finally:
            await app.state.watcher.stop()
            reaper.stopped.set()
            if consumer is not None:
                # SIGTERM stops the consumer at once; interrupted jobs are re-queued by its signal handler.
                consumer.terminate()
                try:
                    consumer.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    consumer.kill()

    app = FastAPI(
        title="Tumblescan",
        version="0.1.0",
        summary="Motion of tumbling space targets from line-scan lidar, as queued jobs.",
        lifespan=lifespan,
        generate_unique_id_function=lambda route: route.name,
    )
    errors.install(app)
    app.add_middleware(errors.InternalErrors)
    app.add_middleware(BodyLimit, max_bytes=s.max_upload_bytes)
    app.include_router(jobs.router)
    app.include_router(kinds.router)
    app.include_router(health.router)
    app.include_router(pages.router)
    return app
