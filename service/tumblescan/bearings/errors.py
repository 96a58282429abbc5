"""Errors of the ``bearings`` kind (codes from the digest's contract)."""

from __future__ import annotations

from ..errors import InputError


class InvalidBearingsInputError(InputError):
    """Anything wrong with a bearings input document; the message names the field."""

    code = "invalid_input"


class TooLargeError(InputError):
    """More detections than a job accepts (HTTP 413)."""

    code = "too_large"
    http_status = 413
