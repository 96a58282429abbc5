"""JSON text read at the door: what is not JSON, or nests past Python's parser (near 1000
levels), is the submitter's error naming the part, never an exception of the parser's own."""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

from ..errors import InputError


def parse_json(
    data: bytes | str,
    field: str,
    *,
    error: type[InputError] = InputError,
    parse_constant: Callable[[str], Any] | None = None,
) -> Any:
    """``json.loads(data)``, refusing with ``error`` naming ``field``.

    ``parse_constant`` is json's hook for the NaN/Infinity tokens (by default they become floats,
    which the caller's validation then refuses with their own field)."""
    try:
        return json.loads(data, parse_constant=parse_constant)
    except json.JSONDecodeError as exc:
        where = f"{exc.msg} at line {exc.lineno} column {exc.colno}"
        raise error(f"{field}: not valid JSON ({where})", field=field) from None
    except UnicodeDecodeError as exc:
        raise error(f"{field}: not valid JSON ({exc})", field=field) from None
    except RecursionError:
        raise error(f"{field}: the JSON nests too deeply to read", field=field) from None
