"""A JSON manifest (meta.json) read at the door: valid JSON, one object, the expected schema
tag, no NaN or Infinity anywhere; every refusal an ``InputError`` naming the field."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from ..errors import InputError


def manifest_object(data: bytes | str, schema: str, *, field: str = "meta") -> dict[str, Any]:
    """The parsed object of a manifest whose ``schema`` must be ``schema``."""
    try:
        raw = json.loads(data)
        bad = first_non_finite(raw)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{field}: not valid JSON ({exc})", field=field) from None
    except RecursionError:  # Python's parser (or the walk above) gives up near 1000 levels
        raise InputError(f"{field}: the JSON nests too deeply to read", field=field) from None
    if bad is not None:
        raise InputError(f"{bad}: not a finite number (NaN and Infinity are refused)", field=bad)
    if not isinstance(raw, dict):
        raise InputError(f"{field}: a JSON object is expected", field=field)
    if raw.get("schema") != schema:
        raise InputError(f"schema: {raw.get('schema')!r} is not {schema!r}", field="schema")
    return raw


def read_manifest(path: Path, *, field: str = "meta") -> bytes:
    """The bytes of the manifest at ``path``."""
    if not path.is_file():
        raise InputError(f"{field}: no such file {path}", field=field)
    return path.read_bytes()


def first_non_finite(value: Any, path: str = "") -> str | None:
    """The dotted path of the first NaN/Infinity in a parsed JSON value, or None."""
    if isinstance(value, float) and not math.isfinite(value):
        return path or "meta"
    items = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else ()
    for key, sub in items:
        found = first_non_finite(sub, f"{path}.{key}" if path else str(key))
        if found is not None:
            return found
    return None
