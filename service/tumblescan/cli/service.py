"""Service commands: ``serve``, ``worker``, ``submit`` and ``demo``."""

from __future__ import annotations

import json
import logging
import os
import signal
import socket
import sys
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
    app.command()(submit)
    app.command()(kinds)
    app.command()(report)


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


def submit(
    files: Annotated[list[str], typer.Argument(help="FILE or PART=FILE; bare files go to the kind's first part")],
    kind: Annotated[str, typer.Option(help="the job kind ('tumblescan kinds' lists them)")] = "linescan-motion",
    cloud: Annotated[Path | None, typer.Option(help="linescan-motion: PLY with per-point times to rectify")] = None,
    truth: Annotated[Path | None, typer.Option(help="truth.json of a simulation, shown in the report")] = None,
    options: Annotated[str, typer.Option(help="job options as JSON")] = "{}",
    wait: Annotated[bool, typer.Option("--wait", help="wait for the result with a progress bar")] = False,
    out: Annotated[Path | None, typer.Option(help="with --wait: write the rectified cloud (linescan) here")] = None,
    artifacts: Annotated[
        Path | None, typer.Option(help="with --wait: download every artifact into this folder")
    ] = None,
    url: Annotated[str | None, typer.Option(help="service URL (TUMBLESCAN_URL)")] = None,
    api_key: Annotated[str | None, typer.Option(help="API key (TUMBLESCAN_API_KEY)")] = None,
    timeout: Annotated[float, typer.Option(help="seconds to wait")] = 600.0,
) -> None:
    """Submit a job of any kind to a running service; print the job, or with --wait its result."""
    from tumblescan_client import TumblescanError

    from ..errors import InputError
    from ..io.json_text import parse_json

    try:
        opts = parse_json(options, "--options")
    except InputError as exc:
        raise fail(str(exc)) from None
    if not isinstance(opts, dict):
        raise fail('--options must be a JSON object, {"name": value, ...}')
    _check_outputs(wait, timeout, out, artifacts)
    client = _client(url, api_key)
    bar = ProgressBar()
    try:
        with client:
            spec = client.kinds.get(kind)
            if out is not None and "cloud" not in {a.name for a in spec.artifacts}:
                raise fail(f"--out writes the rectified cloud, and {kind} has none; use --artifacts DIR")
            # A part of several forms (linescan's 'file': tracks or frames) takes every form's formats.
            formats: dict[str, list[str]] = {}
            for form in spec.forms:
                for part in form.parts:
                    formats.setdefault(part.name, []).extend(part.formats)
            parts = _parts(files, formats, {"cloud": cloud, "truth": truth})
            job = client.jobs.upload(kind, files=parts, options=opts)
            if not wait:
                typer.echo(job.model_dump_json(indent=2))
                return
            job = client.jobs.wait(job.id, timeout=timeout, on_progress=bar)
            bar.end()
            if job.status != "succeeded":
                err = job.error
                typer.echo(
                    f"error: job {job.id} {job.status}" + (f": {err.code}: {err.message}" if err else ""), err=True
                )
                raise typer.Exit(1)
            typer.echo(json.dumps(job.result, indent=2))
            if out is not None and not job.artifacts.cloud:
                raise fail(f"job {job.id} has no rectified cloud (tracks need --cloud); nothing written to {out}")
            if out is not None:
                client.jobs.download_cloud(job.id, out)
                typer.echo(f"wrote {out}", err=True)
            if artifacts is not None:
                artifacts.mkdir(parents=True, exist_ok=True)
                for a in client.jobs.artifacts(job.id):
                    target = client.jobs.download_artifact(job.id, a.name, artifacts / _artifact_file(a))
                    typer.echo(f"wrote {target}", err=True)
    except TumblescanError as exc:
        bar.end()
        raise typer.Exit(_client_error(exc)) from None
    except OSError as exc:  # a download target that cannot be written
        bar.end()
        raise fail(f"cannot write {_target(exc)}: {exc.strerror or exc}") from None


def _check_outputs(wait: bool, timeout: float, out: Path | None, artifacts: Path | None) -> None:
    """Refuse, before anything is submitted, what could only fail (or be ignored) after the
    job has run: outputs without --wait, a timeout that cannot be waited, targets that cannot
    be written."""
    if not 0 < timeout < float("inf"):  # NaN too
        raise fail(f"--timeout must be a finite number of seconds over 0 (got {timeout:g})")
    for flag, given in (("--out", out), ("--artifacts", artifacts)):
        if given is not None and not wait:
            raise fail(f"{flag} needs --wait (the files exist once the job has succeeded)")
    if out is not None and (out.is_dir() or not out.parent.is_dir()):
        raise fail(f"--out {out}: " + ("is a directory" if out.is_dir() else f"no such directory {out.parent}"))
    if artifacts is not None and artifacts.exists() and not artifacts.is_dir():
        raise fail(f"--artifacts {artifacts}: exists and is not a directory")


def _client(url: str | None, api_key: str | None) -> Any:
    """The client, or one line and exit 2 for a service URL it refuses (no scheme)."""
    from tumblescan_client import Client

    try:
        return Client(url, api_key=api_key)
    except ValueError as exc:
        raise fail(str(exc)) from None


def _parts(args: list[str], formats: dict[str, list[str]], named: dict[str, Path | None]) -> dict[str, list[Path]]:
    """Files by upload part (``formats``: each part's file formats, in the kind's order):
    ``PART=FILE`` names its part; a bare file goes to the first part that takes its format (a
    zip to the archive part), else to the first part."""
    parts: dict[str, list[Path]] = {}
    for arg in args:
        name, sep, rest = arg.partition("=")
        if sep and name not in formats and not Path(arg).exists():
            raise fail(f"unknown part {name!r} in {arg!r}: this kind's parts are {', '.join(formats)}")
        part, path = (name, Path(rest)) if sep and name in formats else (_part_for(Path(arg), formats), Path(arg))
        parts.setdefault(part, []).append(path)
    for name, given in named.items():
        if given is not None:
            parts.setdefault(name, []).append(given)
    for paths in parts.values():
        for path in paths:
            if path.is_dir():
                raise fail(f"{path} is a directory; give its files (PART=FILE, one per file) or a zip")
            if not path.is_file():
                raise fail(f"no such file: {path}")
    return parts


def _part_for(path: Path, formats: dict[str, list[str]]) -> str:
    suffix = path.suffix.lower().lstrip(".")
    return next((name for name, taken in formats.items() if suffix in taken), next(iter(formats)))


def _artifact_file(artifact: Any) -> str:
    if getattr(artifact, "filename", None):  # the service names it with the stored file's extension
        return str(Path(artifact.filename).name)
    suffix = {"text/html": ".html", "application/json": ".json", "image/png": ".png"}.get(artifact.media_type, "")
    return artifact.name + ("" if "." in artifact.name else suffix or ".bin")


def _target(exc: OSError) -> str:
    """The file a failed download was for: downloads write ``<target>.part`` and rename it."""
    name = str(exc.filename)
    return name.removesuffix(".part")


def _client_error(exc: Exception) -> int:
    """One line on stderr; exit 2 for what the caller got wrong, 1 for the service's trouble."""
    typer.echo(f"error: {exc}", err=True)
    return 2 if getattr(exc, "status_code", 0) in (400, 401, 403, 404, 409, 413, 422) else 1


def kinds(as_json: Annotated[bool, typer.Option("--json", help="print JSON")] = False) -> None:
    """List the job kinds this installation runs, with their input forms."""
    from ..jobs.registry import kinds as registered

    if as_json:
        listing = [
            {"name": k.name, "title": k.title, "forms": [_form_summary(f) for f in k.forms]}
            for k in registered().values()
        ]
        typer.echo(json.dumps(listing, indent=2))
        return
    for k in registered().values():
        typer.echo(f"{k.name}: {k.title}")
        for f in k.forms:
            via = " (or JSON input)" if f.json_input else ""
            typer.echo(f"    {f.name}: upload {', '.join(p.name for p in f.parts)}{via}")


def _form_summary(form: Any) -> dict[str, Any]:
    return {"name": form.name, "parts": [p.name for p in form.parts], "json_input": form.json_input}


class ProgressBar:
    """A one-line progress bar on stderr fed by ``jobs.wait(on_progress=...)``."""

    def __init__(self, width: int = 30) -> None:
        self.width = width
        self.drawn = False

    def __call__(self, job: Any) -> None:
        filled = round(job.progress * self.width)
        bar = "#" * filled + "-" * (self.width - filled)
        sys.stderr.write(f"\r[{bar}] {100 * job.progress:5.1f} %  {job.status:<9} {job.stage[:28]:<28}")
        sys.stderr.flush()
        self.drawn = True

    def end(self) -> None:
        """End the bar's line, so that what follows (an error) starts a line of its own."""
        if self.drawn:
            sys.stderr.write("\n")
            sys.stderr.flush()
            self.drawn = False


def report(
    job_id: Annotated[str, typer.Argument(help="the job")],
    out: Annotated[Path, typer.Option(help="where to write the HTML report")] = Path("report.html"),
    url: Annotated[str | None, typer.Option(help="service URL (TUMBLESCAN_URL)")] = None,
    api_key: Annotated[str | None, typer.Option(help="API key (TUMBLESCAN_API_KEY)")] = None,
) -> None:
    """Save a finished job's HTML report (self-contained, works offline)."""
    from tumblescan_client import TumblescanError

    if out.is_dir() or not out.parent.is_dir():  # before the download, which may be megabytes
        raise fail(f"--out {out}: " + ("is a directory" if out.is_dir() else f"no such directory {out.parent}"))
    client = _client(url, api_key)
    try:
        with client:
            client.jobs.download_report(job_id, out)
    except TumblescanError as exc:
        raise typer.Exit(_client_error(exc)) from None
    except OSError as exc:  # --out cannot be written
        raise fail(f"cannot write {_target(exc)}: {exc.strerror or exc}") from None
    typer.echo(f"wrote {out}")
