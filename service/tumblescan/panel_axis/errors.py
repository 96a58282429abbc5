"""The kind's refusals (codes are the API; see docs/panel_axis.md)."""

from __future__ import annotations

from ..errors import InputError
from ..imaging.image_io import UnreadableImageError


class NoTargetError(InputError):
    code = "no_target"


class TooFewEdgesError(InputError):
    code = "too_few_edges"


class DegenerateViewError(InputError):
    code = "degenerate_view"


class DepthUnobservableError(InputError):
    code = "depth_unobservable"


__all__ = [
    "DegenerateViewError",
    "DepthUnobservableError",
    "InputError",
    "NoTargetError",
    "TooFewEdgesError",
    "UnreadableImageError",
]
