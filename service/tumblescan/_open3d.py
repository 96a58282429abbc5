"""Open3D, loaded on first use and told to keep quiet: below errors it prints to stdout from
C++, which would break ``--json`` output (one JSON document on stdout and nothing else)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from functools import cache
from typing import Any


@cache
def load_open3d() -> Any:
    """The ``open3d`` module, its log level set to errors only."""
    import open3d

    open3d.utility.set_verbosity_level(open3d.utility.VerbosityLevel.Error)
    return open3d


@contextmanager
def one_thread() -> Iterator[Any]:
    """Open3D on one thread inside the block, restored after it; yields the module.

    Its parallel loops (TBB) ignore ``OMP_NUM_THREADS``, and RANSAC's draws across threads
    depend on their timing whatever the seed: the same frames registered twice in one process
    gave one pair another transform, and two runs of the real-shapes bench differed on 5 of 15
    cases (a sigma by 3.5 %, the points used). One thread makes a seeded estimate repeatable."""
    o3d = load_open3d()
    before = o3d.utility.get_max_threads()
    o3d.utility.set_max_threads(1)
    try:
        yield o3d
    finally:
        o3d.utility.set_max_threads(before)
