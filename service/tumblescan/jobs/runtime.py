"""Per-process runtime: settings, store and artifact store, built lazily after any fork
(a database connection must never cross a fork)."""

from __future__ import annotations

import os
from dataclasses import dataclass

from ..settings import Settings, get_settings
from .artifacts import ArtifactStore
from .store import JobStore


@dataclass
class Runtime:
    settings: Settings
    store: JobStore
    artifacts: ArtifactStore


_runtime: tuple[int, Runtime] | None = None


def get_runtime(settings: Settings | None = None) -> Runtime:
    global _runtime
    if _runtime is None or _runtime[0] != os.getpid():
        s = settings or get_settings()
        s.data_dir.mkdir(parents=True, exist_ok=True)
        _runtime = (os.getpid(), Runtime(s, JobStore(s.db_url), ArtifactStore(s.artifacts)))
    return _runtime[1]
