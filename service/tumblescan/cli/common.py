"""What every command shares: bad input is exit code 2 and one line on stderr, never a traceback."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from functools import wraps
from typing import Any, TypeVar

import typer

from ..errors import InputError

F = TypeVar("F", bound=Callable[..., Any])


def fail(message: str) -> typer.Exit:
    typer.echo(f"error: {message}", err=True)
    return typer.Exit(code=2)


def input_errors(fn: F) -> F:
    """Turn bad input into exit code 2 and one line on stderr, never a traceback."""

    @wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except InputError as exc:
            raise fail(str(exc)) from None
        except FileNotFoundError as exc:
            raise fail(f"no such file: {exc.filename}") from None
        except IsADirectoryError as exc:  # a rename names its target second
            raise fail(f"{exc.filename2 or exc.filename} is a directory, not a file") from None
        except UnicodeDecodeError as exc:
            raise fail(str(exc)) from None
        except RecursionError:  # json gives up on input nested near 1000 levels deep
            raise fail("an input file's JSON nests too deeply to read") from None
        except OSError as exc:  # permission denied, a read-only or full disk: one line all the same
            where = exc.filename2 or exc.filename
            raise fail(f"{where}: {exc.strerror or exc}" if where else str(exc)) from None

    return wrapper  # type: ignore[return-value]


@contextmanager
def json_stdout(active: bool) -> Iterator[None]:
    """With ``--json``, stdout carries one JSON document and nothing else: while the work runs,
    whatever writes to stdout (Python or C, such as a library's warnings) goes to stderr."""
    if not active:
        yield
        return
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        os.dup2(2, 1)
        yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)
