"""A JSON manifest (meta.json) read at the door: valid JSON, one object, the expected schema
tag, no NaN or Infinity anywhere; every refusal an ``InputError`` naming the field."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from ..errors import InputError
from .json_text import parse_json


def manifest_object(data: bytes | str, schema: str, *, field: str = "meta") -> dict[str, Any]:
    """The parsed object of a manifest whose ``schema`` must be ``schema``."""
    raw = parse_json(data, field)
    bad = first_non_finite(raw)
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
    """The dotted path of the first NaN/Infinity in a parsed JSON value, or None. A walk with its
    own stack: a document as deep as the parser allows must not overflow Python's."""
    stack: list[tuple[Any, str]] = [(value, path)]
    while stack:
        node, where = stack.pop()
        if isinstance(node, float) and not math.isfinite(node):
            return where or "meta"
        items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
        children = [(sub, f"{where}.{key}" if where else str(key)) for key, sub in items]
        stack.extend(reversed(children))  # the first child is looked at first
    return None
