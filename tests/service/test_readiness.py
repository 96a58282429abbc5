"""A worker announces itself before its consumer starts, so /readyz turns ready as soon as
jobs can be taken (the housekeeper's first heartbeat comes seconds later, after its imports)."""

from __future__ import annotations

from pathlib import Path

from tumblescan.cli.service import _announce
from tumblescan.jobs.store import JobStore
from tumblescan.settings import Settings


def test_a_worker_is_counted_live_as_soon_as_it_announces_itself(tmp_path: Path) -> None:
    settings = Settings(data_dir=tmp_path, workers=3)
    store = JobStore(settings.db_url)
    assert store.live_worker_processes(15.0) == 0
    _announce(settings, "host-123")
    assert store.live_worker_processes(15.0) == 3
    store.worker_gone("host-123")
    assert store.live_worker_processes(15.0) == 0
