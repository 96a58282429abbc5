"""Open3D, loaded on first use and told to keep quiet: below errors it prints to stdout from
C++, which would break ``--json`` output (one JSON document on stdout and nothing else)."""

from __future__ import annotations

from functools import cache
from typing import Any


@cache
def load_open3d() -> Any:
    """The ``open3d`` module, its log level set to errors only."""
    import open3d

    open3d.utility.set_verbosity_level(open3d.utility.VerbosityLevel.Error)
    return open3d
