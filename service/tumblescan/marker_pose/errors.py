"""The refusals of marker-pose-graph (each an ``InputError`` with a stable ``code`` and the field at
fault). The shared ones (non-finite values, duplicates, time order, too few frames, limits,
malformed documents, bad options) come from ``tumblescan.errors``."""

from __future__ import annotations

from ..errors import (
    InputError,
    InvalidOptionError,
    LimitExceededError,
    MalformedInputError,
    NonFiniteValueError,
    TimeOrderError,
    UnknownFieldError,
)


class DuplicateObservationError(InputError):
    code = "duplicate_observation"


class TooFewFramesError(InputError):
    code = "too_few_frames"


class UnsupportedUnitsError(InputError):
    code = "unsupported_units"


class DegenerateLayoutError(InputError):
    code = "degenerate_layout"


class DuplicateMarkerIdError(InputError):
    code = "duplicate_marker_id"


class LayoutScaleError(InputError):
    code = "layout_scale"


class NoiseOutOfRangeError(InputError):
    code = "noise_out_of_range"


class OutOfVolumeError(InputError):
    code = "out_of_volume"


__all__ = [
    "DegenerateLayoutError",
    "DuplicateMarkerIdError",
    "DuplicateObservationError",
    "InputError",
    "InvalidOptionError",
    "LayoutScaleError",
    "LimitExceededError",
    "MalformedInputError",
    "NoiseOutOfRangeError",
    "NonFiniteValueError",
    "OutOfVolumeError",
    "TimeOrderError",
    "TooFewFramesError",
    "UnknownFieldError",
    "UnsupportedUnitsError",
]
