"""Start-up checks: a directory the service's user cannot write, an unreachable database or
queue, each gives one line naming the path or URL and what to do."""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from tests import infra
from tumblescan.preflight import check_queue, check_store, check_writable_dirs, start_up_problem
from tumblescan.settings import Settings

NOBODY = 65534
CLOSED_PORT = 1  # nothing listens on 127.0.0.1:1: connections are refused at once


@pytest.fixture
def shared_dir() -> Iterator[Path]:
    """A directory every user may enter (pytest's tmp_path is private to root)."""
    d = Path(tempfile.mkdtemp(prefix="tumblescan-preflight-"))
    d.chmod(0o755)
    yield d
    shutil.rmtree(d, ignore_errors=True)


@contextmanager
def as_service_user() -> Iterator[int]:
    """Run the block as an unprivileged user, as the container does (uid 10001 there): as root,
    switch the effective uid; otherwise the caller already is one."""
    if os.geteuid() != 0:
        yield os.geteuid()
        return
    os.setegid(NOBODY)
    os.seteuid(NOBODY)
    try:
        yield NOBODY
    finally:
        os.seteuid(0)
        os.setegid(0)


def one_line(problem: str | None) -> str:
    assert problem is not None
    assert "\n" not in problem
    return problem


def test_root_owned_data_dir_names_the_path_the_uid_and_the_fix(shared_dir: Path) -> None:
    data = shared_dir / "data"
    data.mkdir(mode=0o755)  # owned by whoever runs the tests, as a root-owned volume mounted at /data
    if os.geteuid() != 0:
        data.chmod(0o555)
    with as_service_user() as uid:
        problem = one_line(start_up_problem(Settings(data_dir=data)))
    assert problem.startswith(f"data directory {data} is not writable by uid {uid} (permission denied): ")
    assert f"chown it to uid {uid}" in problem
    assert "TUMBLESCAN_DATA_DIR" in problem


def test_missing_data_dir_under_a_root_owned_parent_cannot_be_created(shared_dir: Path) -> None:
    if os.geteuid() != 0:
        shared_dir.chmod(0o555)
    data = shared_dir / "data"
    with as_service_user() as uid:
        problem = one_line(check_writable_dirs(Settings(data_dir=data)))
    shared_dir.chmod(0o755)
    assert problem.startswith(f"data directory {data} cannot be created by uid {uid} (permission denied): ")


def test_a_file_where_the_data_dir_belongs(tmp_path: Path) -> None:
    data = tmp_path / "data"
    data.write_text("not a directory")
    problem = one_line(check_writable_dirs(Settings(data_dir=data)))
    assert problem.startswith(f"data directory {data} is not a directory: ")
    assert "TUMBLESCAN_DATA_DIR" in problem


def test_artifact_dir_beneath_a_file_names_the_artifact_setting(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("x")
    artifacts = tmp_path / "file" / "artifacts"
    problem = one_line(check_writable_dirs(Settings(data_dir=tmp_path / "data", artifact_dir=artifacts)))
    assert problem.startswith(
        f"artifact directory {artifacts} cannot be reached by uid {os.geteuid()} (not a directory): "
    )
    assert "TUMBLESCAN_ARTIFACT_DIR" in problem


def test_writable_dirs_are_made_and_pass(tmp_path: Path) -> None:
    s = Settings(data_dir=tmp_path / "new" / "data")
    assert start_up_problem(s) is None
    assert s.artifacts.is_dir()
    assert list(s.data_dir.iterdir()) == [s.artifacts]  # the write test leaves nothing behind


def test_read_only_sqlite_job_database_names_the_file(shared_dir: Path) -> None:
    data = shared_dir / "data"
    data.mkdir(mode=0o777)
    data.chmod(0o777)  # the directory is writable, the database file in it is not
    db = data / "jobs.db"
    db.write_bytes(b"")
    db.chmod(0o444)
    with as_service_user() as uid:
        problem = one_line(check_store(f"sqlite:///{db}"))
    assert problem.startswith(f"job database {db} is not writable by uid {uid} (permission denied): ")


def test_unreachable_postgres_names_the_url_without_its_password() -> None:
    url = f"postgresql+psycopg://tumblescan:s3cret@127.0.0.1:{CLOSED_PORT}/tumblescan"
    problem = one_line(check_store(url))
    assert problem.startswith(
        f"job database postgresql+psycopg://tumblescan:***@127.0.0.1:{CLOSED_PORT}/tumblescan is not reachable ("
    )
    assert "refused" in problem.lower()
    assert problem.endswith("start it or fix TUMBLESCAN_DATABASE_URL")
    assert "s3cret" not in problem


def test_unreachable_postgres_stops_start_up(tmp_path: Path) -> None:
    url = f"postgresql+psycopg://tumblescan@127.0.0.1:{CLOSED_PORT}/tumblescan"
    problem = one_line(start_up_problem(Settings(data_dir=tmp_path, database_url=url)))
    assert "is not reachable" in problem and "TUMBLESCAN_DATABASE_URL" in problem


def test_not_a_database_url() -> None:
    problem = one_line(check_store("postgres at the usual place"))
    assert (
        problem == "job database URL 'postgres at the usual place' is not a database URL: fix TUMBLESCAN_DATABASE_URL"
    )


def test_reachable_postgres_passes() -> None:
    with infra.postgres_database() as url:
        assert check_store(url) is None


def test_unreachable_redis_names_the_url_without_its_password(tmp_path: Path) -> None:
    s = Settings(data_dir=tmp_path, redis_url=f"redis://:s3cret@127.0.0.1:{CLOSED_PORT}/0")
    problem = one_line(check_queue(s))
    assert problem.startswith(f"queue redis://:***@127.0.0.1:{CLOSED_PORT}/0 is not reachable (")
    assert problem.endswith("start Redis there or fix TUMBLESCAN_REDIS_URL")
    assert "s3cret" not in problem


def test_not_a_redis_url(tmp_path: Path) -> None:
    problem = one_line(check_queue(Settings(data_dir=tmp_path, redis_url="http://127.0.0.1:6379")))
    assert problem.startswith("queue URL http://127.0.0.1:6379 is not a Redis URL (")


def test_reachable_redis_passes(tmp_path: Path) -> None:
    infra.ensure_redis()
    assert check_queue(Settings(data_dir=tmp_path, redis_url=infra.REDIS_URL)) is None
