"""Editing a simulated input document to break one field."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any


def set_at(path: list[Any], value: Any) -> Callable[[dict[str, Any]], None]:
    """An edit that sets ``doc[path[0]][path[1]]...`` to ``value``."""

    def f(doc: dict[str, Any]) -> None:
        target = doc
        for p in path[:-1]:
            target = target[p]
        target[path[-1]] = value

    return f
