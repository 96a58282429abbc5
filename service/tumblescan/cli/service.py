"""Running the service: ``serve`` (the API with its workers) and ``worker`` (scale-out)."""

from __future__ import annotations

import logging
import os
import signal
import socket
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from .common import fail

if TYPE_CHECKING:
    from ..settings import Settings


def _settings(**overrides: Any) -> Settings:
    """The settings from the flags over the environment; a value they refuse (a port over
    65535, TUMBLESCAN_WORKERS=abc) is one line and exit 2, naming the setting."""
    from pydantic import ValidationError

    from ..settings import Settings

    try:
        return Settings(**{k: v for k, v in overrides.items() if v is not None})
    except ValidationError as exc:
        e = exc.errors(include_url=False)[0]
        name = ".".join(str(p) for p in e["loc"])
        raise fail(f"setting {name} (--{name.replace('_', '-')} or TUMBLESCAN_{name.upper()}): {e['msg']}") from None


def _bind_problem(host: str, port: int) -> str | None:
    """Why ``serve`` could not listen on host:port (in use, not an address here), or None.
    Checked before anything starts, so the answer is one line rather than uvicorn's log."""
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except OSError as exc:
        return f"cannot listen on {host}:{port}: {exc.strerror or exc}"
    family, _, _, _, address = infos[0]
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as uvicorn binds
        try:
            probe.bind(address)
        except OSError as exc:
            return (
                f"cannot listen on {host}:{port}: {exc.strerror or exc} (--port or TUMBLESCAN_PORT to choose another)"
            )
    return None


def _logging() -> None:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")


def register(app: typer.Typer) -> None:
    app.command()(serve)
    app.command()(worker)


def serve(
    host: Annotated[str | None, typer.Option(help="default 127.0.0.1 (TUMBLESCAN_HOST)")] = None,
    port: Annotated[int | None, typer.Option(help="default 8000 (TUMBLESCAN_PORT)")] = None,
    workers: Annotated[int | None, typer.Option(min=1, help="worker processes; default one per core")] = None,
    no_workers: Annotated[bool, typer.Option("--no-workers", help="API only (workers run elsewhere)")] = False,
    data_dir: Annotated[Path | None, typer.Option(help="TUMBLESCAN_DATA_DIR")] = None,
    redis_url: Annotated[str | None, typer.Option(help="TUMBLESCAN_REDIS_URL")] = None,
    database_url: Annotated[str | None, typer.Option(help="TUMBLESCAN_DATABASE_URL")] = None,
) -> None:
    """Run the HTTP API with its worker pool (embedded SQLite queue and store by default).

    API keys come only from the environment: TUMBLESCAN_API_KEYS, TUMBLESCAN_ADMIN_KEYS."""
    import uvicorn

    from ..api.app import create_app

    _logging()
    s = _settings(
        host=host, port=port, workers=workers, data_dir=data_dir, redis_url=redis_url, database_url=database_url
    )
    problem = s.open_access_problem()
    if problem:
        typer.echo(f"error: {problem}", err=True)
        raise typer.Exit(2)
    from ..preflight import start_up_problem

    if problem := start_up_problem(s) or _bind_problem(s.host, s.port):
        raise fail(problem)
    if not (s.api_keys or s.admin_keys):
        typer.echo(
            f"tumblescan: no API keys configured: anyone who can reach {s.host}:{s.port} may use the service", err=True
        )
    n = 0 if no_workers else s.workers
    typer.echo(
        f"tumblescan: serving on http://{s.host}:{s.port} with {n} worker process(es); data in {s.data_dir}", err=True
    )
    uvicorn.run(create_app(s, embedded_workers=n), host=s.host, port=s.port, log_level="warning")


def worker(
    workers: Annotated[int | None, typer.Option(min=1, help="worker processes; default one per core")] = None,
    data_dir: Annotated[Path | None, typer.Option(help="TUMBLESCAN_DATA_DIR: artifacts (shared with the API)")] = None,
    redis_url: Annotated[str | None, typer.Option(help="TUMBLESCAN_REDIS_URL: the queue (shared)")] = None,
    database_url: Annotated[str | None, typer.Option(help="TUMBLESCAN_DATABASE_URL: the job store (shared)")] = None,
) -> None:
    """Run queue workers (scale-out: on any machine sharing the store, queue and artifacts)."""
    import multiprocessing

    from ..jobs.queue import make_huey

    _logging()
    overrides = {"workers": workers, "data_dir": data_dir, "redis_url": redis_url, "database_url": database_url}
    s = _settings(**overrides)
    from ..preflight import start_up_problem

    if problem := start_up_problem(s):
        raise fail(problem)
    share_cores(s.workers)
    huey, _ = make_huey(s)
    _announce(s, f"{socket.gethostname()}-{os.getpid()}")
    # This process forks the worker processes (now and whenever one dies), so it must never
    # hold the job store open: SQLite's lock bookkeeping does not survive a fork. Heartbeat
    # and reaper run in a separate, spawned process.
    housekeeper = multiprocessing.get_context("spawn").Process(
        target=housekeeping, args=({k: v for k, v in overrides.items() if v is not None}, os.getpid()), daemon=True
    )
    housekeeper.start()
    consumer = huey.create_consumer(
        workers=s.workers,
        worker_type="process",
        periodic=False,
        initial_delay=s.poll_initial_delay_s,
        max_delay=s.poll_max_delay_s,
        backoff=1.15,
    )
    try:
        consumer.run()
    finally:
        housekeeper.terminate()
        housekeeper.join(timeout=10)


THREAD_POOL_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def share_cores(workers: int) -> None:
    """Size each worker process's BLAS/OpenMP pools to its share of the cores, unless the
    environment already does. Forked before numpy is loaded, each worker would otherwise start a
    pool of every core, and ``workers`` of them oversubscribe the machine (a spin-from-images
    sequence measured about 6x slower with two workers on two cores)."""
    threads = str(max(1, (os.cpu_count() or 1) // workers))
    for var in THREAD_POOL_VARS:
        os.environ.setdefault(var, threads)


def _announce(s: Settings, worker_id: str) -> None:
    """The first worker heartbeat, before the consumer starts (the housekeeper's first beat
    comes seconds later, after its imports), so /readyz says ready as soon as jobs can be
    taken. The store is closed again: this process forks the workers."""
    from ..jobs.store import JobStore

    store = JobStore(s.db_url)
    try:
        store.worker_heartbeat(worker_id, socket.gethostname(), s.workers)
    finally:
        store.close()


def housekeeping(overrides: dict[str, Any], consumer_pid: int) -> None:
    """Worker heartbeat (for /readyz) and the reaper, beside a consumer, until it is gone."""
    from ..jobs.queue import make_huey
    from ..jobs.runtime import get_runtime
    from ..jobs.service import JobService

    _logging()
    s = _settings(**overrides)
    rt = get_runtime(s)
    huey, task = make_huey(s)
    service = JobService(rt, task, huey.pending_count)
    worker_id = f"{socket.gethostname()}-{consumer_pid}"
    log = logging.getLogger("tumblescan.worker")
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    last_reap = 0.0
    try:
        while not stop.is_set() and os.getppid() == consumer_pid:
            try:
                rt.store.worker_heartbeat(worker_id, socket.gethostname(), s.workers)
                if time.monotonic() - last_reap >= s.reaper_interval_s:
                    last_reap = time.monotonic()
                    service.reap_once()
            except Exception:
                log.exception("housekeeping pass failed")
            stop.wait(min(s.heartbeat_s, s.reaper_interval_s))
    finally:
        rt.store.worker_gone(worker_id)
