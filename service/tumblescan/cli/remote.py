"""Commands against a running service, through the client: ``submit``, ``kinds`` and ``report``."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from .common import fail


def register(app: typer.Typer) -> None:
    app.command()(submit)
    app.command()(kinds)
    app.command()(report)


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
    if out is not None:
        _check_out(out)
    if artifacts is not None and artifacts.exists() and not artifacts.is_dir():
        raise fail(f"--artifacts {artifacts}: exists and is not a directory")


def _check_out(out: Path) -> None:
    """A download's target: not a directory, in one that exists."""
    if out.is_dir() or not out.parent.is_dir():
        raise fail(f"--out {out}: " + ("is a directory" if out.is_dir() else f"no such directory {out.parent}"))


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

    _check_out(out)  # before the download, which may be megabytes
    client = _client(url, api_key)
    try:
        with client:
            client.jobs.download_report(job_id, out)
    except TumblescanError as exc:
        raise typer.Exit(_client_error(exc)) from None
    except OSError as exc:  # --out cannot be written
        raise fail(f"cannot write {_target(exc)}: {exc.strerror or exc}") from None
    typer.echo(f"wrote {out}")
