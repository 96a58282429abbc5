"""Start-up checks for ``serve`` and ``worker``: the directories, the job store and the queue.

Each check returns ``None`` when all is well, or one line that names the path or URL, what is
wrong and what to do, for example ``data directory /data is not writable by uid 10001
(permission denied): chown it to uid 10001 or mount a writable volume there
(TUMBLESCAN_DATA_DIR)``. The commands print it and exit non-zero instead of failing later with
a traceback from SQLite, psycopg or redis. Every check really writes or connects: permission
bits say nothing about read-only mounts, and root may write where the service's user may not.
"""

from __future__ import annotations

import os
import re
import stat
import tempfile
from pathlib import Path
from urllib.parse import urlsplit, urlunsplit

from .settings import Settings

CONNECT_TIMEOUT_S = 5


def start_up_problem(settings: Settings) -> str | None:
    """The first problem that would stop the service from running jobs, or None."""
    return check_writable_dirs(settings) or check_store(settings.db_url) or check_queue(settings)


def check_writable_dirs(settings: Settings) -> str | None:
    """The data directory and the artifact directory exist (or can be made) and can be written."""
    dirs = [("data directory", settings.data_dir, "TUMBLESCAN_DATA_DIR")]
    if settings.artifact_dir is not None:
        dirs.append(("artifact directory", settings.artifact_dir, "TUMBLESCAN_ARTIFACT_DIR"))
    else:
        dirs.append(("artifact directory", settings.artifacts, "TUMBLESCAN_DATA_DIR or TUMBLESCAN_ARTIFACT_DIR"))
    for what, path, setting in dirs:
        problem = _dir_problem(what, path, setting)
        if problem:
            return problem
    return None


def check_store(url: str) -> str | None:
    """The job database at ``url`` (a SQLAlchemy URL) answers; a SQLite file can be written."""
    from sqlalchemy import create_engine, text
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError, NoSuchModuleError, SQLAlchemyError
    from sqlalchemy.pool import NullPool

    try:
        parsed = make_url(url)
    except ArgumentError:
        return f"job database URL {url!r} is not a database URL: fix TUMBLESCAN_DATABASE_URL"
    shown = parsed.render_as_string(hide_password=True)
    if parsed.get_backend_name() == "sqlite":
        if not parsed.database or parsed.database == ":memory:":
            return f"job database {shown} would keep nothing: give a SQLite file or a server (TUMBLESCAN_DATABASE_URL)"
        return _sqlite_problem("job database", Path(parsed.database), "TUMBLESCAN_DATABASE_URL or TUMBLESCAN_DATA_DIR")
    connect_args = {"connect_timeout": CONNECT_TIMEOUT_S} if parsed.get_backend_name() == "postgresql" else {}
    try:
        engine = create_engine(parsed, poolclass=NullPool, connect_args=connect_args)
    except (NoSuchModuleError, ImportError) as exc:
        reason = _one_line(exc)
        return f"job database {shown} needs a driver this installation lacks ({reason}): fix TUMBLESCAN_DATABASE_URL"
    try:
        with engine.connect() as conn:
            conn.execute(text("SELECT 1"))
    except SQLAlchemyError as exc:
        reason = _one_line(getattr(exc, "orig", None) or exc)
        return f"job database {shown} is not reachable ({reason}): start it or fix TUMBLESCAN_DATABASE_URL"
    finally:
        engine.dispose()
    return None


def check_queue(settings: Settings) -> str | None:
    """The Redis queue answers a PING, or the embedded SQLite queue file can be written."""
    if not settings.redis_url:
        return _sqlite_problem("queue", settings.data_dir / "queue.db", "TUMBLESCAN_DATA_DIR")
    import redis

    shown = _hide_password(settings.redis_url)
    try:
        client = redis.Redis.from_url(
            settings.redis_url, socket_connect_timeout=CONNECT_TIMEOUT_S, socket_timeout=CONNECT_TIMEOUT_S
        )
    except ValueError as exc:
        return f"queue URL {shown} is not a Redis URL ({_one_line(exc)}): fix TUMBLESCAN_REDIS_URL"
    try:
        client.ping()
    except redis.RedisError as exc:
        return f"queue {shown} is not reachable ({_one_line(exc)}): start Redis there or fix TUMBLESCAN_REDIS_URL"
    finally:
        client.close()
    return None


def _dir_problem(what: str, path: Path, setting: str) -> str | None:
    """Why ``path`` cannot serve as a writable directory (made if missing), or None."""
    uid = os.geteuid()
    fix = f"mount a writable volume there or point {setting} elsewhere"
    try:
        if not stat.S_ISDIR(path.stat().st_mode):
            return f"{what} {path} is not a directory: {fix}"
    except FileNotFoundError:
        try:
            path.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            return f"{what} {path} cannot be created by uid {uid} ({_reason(exc)}): create it for uid {uid}, {fix}"
    except OSError as exc:  # a parent that is not a directory, or not searchable by this user
        return f"{what} {path} cannot be reached by uid {uid} ({_reason(exc)}): {fix}"
    try:
        with tempfile.TemporaryFile(dir=path, prefix=".tumblescan-write-test-"):
            pass
    except OSError as exc:
        return f"{what} {path} is not writable by uid {uid} ({_reason(exc)}): chown it to uid {uid}, {fix}"
    return None


def _sqlite_problem(what: str, path: Path, setting: str) -> str | None:
    """Why SQLite could not write ``path`` (its directory holds the journal), or None."""
    problem = _dir_problem(f"{what}'s directory", path.parent, setting)
    if problem:
        return problem
    uid = os.geteuid()
    try:
        with open(path, "r+b"):
            pass
    except FileNotFoundError:
        return None  # made on first use, in a directory known to be writable
    except OSError as exc:
        return f"{what} {path} is not writable by uid {uid} ({_reason(exc)}): chown it to uid {uid} or change {setting}"
    return None


def _reason(exc: OSError) -> str:
    return (exc.strerror or type(exc).__name__).lower()


def _one_line(exc: BaseException) -> str:
    """The first line of an exception's message, whitespace collapsed (drivers write paragraphs)."""
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    text = re.sub(r"\s+", " ", lines[0]) if lines else type(exc).__name__
    return text[:200]


def _hide_password(url: str) -> str:
    parts = urlsplit(url)
    if parts.password is None:
        return url
    netloc = parts.netloc.rsplit("@", 1)
    user = (parts.username or "") + ":***"
    return urlunsplit(parts._replace(netloc=f"{user}@{netloc[1]}"))
