"""Input errors: one ``ValueError`` subclass per problem, each naming what is wrong.

``code`` is a stable machine-readable name (the API returns it); ``field`` names the input
field at fault where there is one.
"""

from __future__ import annotations


class InputError(ValueError):
    """Bad input to Tumblescan; the message says what and where. ``http_status`` is what the
    API answers when it is found at submission (422 unless a kind's contract says otherwise)."""

    code = "invalid_input"
    http_status = 422

    def __init__(self, message: str, *, field: str | None = None) -> None:
        super().__init__(message)
        self.field = field


class MalformedInputError(InputError):
    code = "malformed_input"


class UnknownFieldError(InputError):
    code = "unknown_field"


class NonFiniteValueError(InputError):
    code = "non_finite_value"


class TimeOrderError(InputError):
    code = "time_out_of_order"


class MissingTimeError(InputError):
    code = "missing_time"


class InvalidOptionError(InputError):
    code = "invalid_option"


class LimitExceededError(InputError):
    code = "limit_exceeded"
