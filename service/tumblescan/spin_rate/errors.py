"""The kind's refusals; the codes are the API (digest §6(c), docs/spin_rate.md)."""

from __future__ import annotations

from ..errors import InputError
from ..imaging.image_io import UnreadableImageError


class NoTargetError(InputError):
    code = "no_target"


class UndersampledError(InputError):
    code = "undersampled"


class TooFewFeaturesError(InputError):
    code = "too_few_features"


class NotConvergedError(InputError):
    code = "not_converged"


__all__ = [
    "InputError",
    "NoTargetError",
    "NotConvergedError",
    "TooFewFeaturesError",
    "UndersampledError",
    "UnreadableImageError",
]
