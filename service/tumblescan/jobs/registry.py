"""The job kinds this service runs: an explicit list, so what is served is what is written
here (no registration by import side effect). Adding a kind is one line below; see
docs/adding-a-kind.md."""

from __future__ import annotations

from functools import cache

from ..errors import InputError
from .kind import JobKind


class UnknownKindError(InputError):
    code = "unknown_kind"


@cache
def kinds() -> dict[str, JobKind]:
    """Every kind by name (built once per process; adapters import their cores lazily)."""
    from .kinds.bearings import Bearings
    from .kinds.linescan import LinescanMotion
    from .kinds.marker_pose import MarkerPoseGraph
    from .kinds.panel_axis import PanelAxis
    from .kinds.spin_rate import SpinFromImages

    listed: list[JobKind] = [
        LinescanMotion(),
        PanelAxis(),
        MarkerPoseGraph(),
        Bearings(),
        SpinFromImages(),
    ]
    return {k.name: k for k in listed}


def get_kind(name: str) -> JobKind:
    """The kind called ``name``; ``UnknownKindError`` (a 422 naming ``kind``) otherwise."""
    found = kinds().get(name)
    if found is None:
        raise UnknownKindError(f"unknown job kind {name!r}; known: {', '.join(kind_names())}", field="kind")
    return found


def kind_names() -> list[str]:
    return sorted(kinds())
