"""Bad line-scan input: each error names what is wrong (``code`` for the API, ``field`` for
the input field at fault). The generic ones (malformed input, non-finite values, limits) are
in ``tumblescan.errors``."""

from __future__ import annotations

from ..errors import InputError


class TooFewFramesError(InputError):
    code = "too_few_frames"


class TooFewTracksError(InputError):
    code = "too_few_tracks"


class DuplicateObservationError(InputError):
    code = "duplicate_observation"


class SingleObservationTrackError(InputError):
    code = "single_observation_track"


class NotInitializableError(InputError):
    """The closed-form start was asked for (strategy 'lm') and the tracks do not support it."""

    code = "not_initializable"


class FramesUnusableError(InputError):
    code = "frames_unusable"


class NoSurfacesError(FramesUnusableError):
    """No planar patch matched across frames: a property of the data, not of the start, so
    no other start is tried."""
