"""What every command shares: bad input is exit code 2 and one line on stderr, never a traceback."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from functools import wraps
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import typer
from typer.core import TyperGroup

try:  # typer 0.29 carries its own click; earlier ones use click's
    from typer._click.exceptions import ClickException, NoArgsIsHelpError, UsageError
except ImportError:  # pragma: no cover
    from click.exceptions import ClickException, NoArgsIsHelpError, UsageError  # type: ignore[assignment]

from ..errors import InputError, InvalidOptionError

if TYPE_CHECKING:
    from pydantic import BaseModel

F = TypeVar("F", bound=Callable[..., Any])
M = TypeVar("M", bound="BaseModel")


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
        except ValueError as exc:  # options built from flags: a value out of range names its field
            from pydantic import ValidationError  # here, not at import: `tumblescan --help` stays fast

            if not isinstance(exc, ValidationError):
                raise
            raise fail(first_error(exc)) from None
        except RecursionError:  # json gives up on input nested near 1000 levels deep
            raise fail("an input file's JSON nests too deeply to read") from None
        except OSError as exc:  # permission denied, a read-only or full disk: one line all the same
            where = exc.filename2 or exc.filename
            raise fail(f"{where}: {exc.strerror or exc}" if where else str(exc)) from None

    return wrapper  # type: ignore[return-value]


def check_output_files(**paths: Path | None) -> None:
    """Output files (keyword: the option's name, ``report_html`` for ``--report-html``) checked
    before any work: each one's directory exists, it is not a directory itself and no two are one
    file. A command refused here has written nothing; one refused after its work may have
    written a first output."""
    seen: dict[Path, str] = {}
    for name, path in paths.items():
        if path is None:
            continue
        option = "--" + name.replace("_", "-")
        if path.is_dir():
            raise InputError(f"{option}: {path} is a directory; give a file name", field=name)
        if not path.parent.is_dir():
            raise InputError(f"{option}: the directory {path.parent} does not exist", field=name)
        # One output written over another would lose the first.
        if (other := seen.setdefault(path.resolve(), option)) != option:
            raise InputError(f"{other} and {option} are the same file ({path}); give two names", field=name)


def options_from_flags(model: type[M], values: dict[str, Any], *, flags: dict[str, str] | None = None) -> M:
    """``model`` validated from the flags' ``values``; a refusal names the flag (``flags``, else
    ``--name``), not the field, so the user reads the option they typed."""
    from pydantic import ValidationError

    try:
        return model.model_validate(values)
    except ValidationError as exc:
        e = exc.errors(include_url=False)[0]
        name = str(e["loc"][0]) if e["loc"] else "options"
        flag = (flags or {}).get(name, "--" + name.replace("_", "-"))
        raise InvalidOptionError(f"{flag}: {e['msg']}", field=name) from None


def first_error(exc: Any) -> str:
    """The first error of a pydantic ``ValidationError`` as 'dotted.location: message'."""
    e = exc.errors(include_url=False)[0]
    where = ".".join(str(p) for p in e["loc"]) or exc.title
    return f"{where}: {e['msg']}"


class OneLineErrors(TyperGroup):
    """The root command group: a usage error (an unknown option, a value out of range, a
    missing argument) is ``error: ...`` on one line with exit code 2, like every other bad
    input, instead of click's usage box of five or more lines."""

    def main(
        self,
        args: Sequence[str] | None = None,
        prog_name: str | None = None,
        complete_var: str | None = None,
        standalone_mode: bool = True,
        windows_expand_args: bool = True,
        **kwargs: Any,
    ) -> Any:
        try:
            rv = super().main(args, prog_name, complete_var, False, windows_expand_args, **kwargs)
        except NoArgsIsHelpError as exc:  # a bare group: its help, as before
            exc.show()
            rv = exc.exit_code
        except UsageError as exc:
            hint = f" (see '{exc.ctx.command_path} --help')" if exc.ctx is not None else ""
            typer.echo(f"error: {exc.format_message()}{hint}", err=True)
            rv = exc.exit_code
        except ClickException as exc:
            typer.echo(f"error: {exc.format_message()}", err=True)
            rv = exc.exit_code
        except typer.Abort:
            typer.echo("aborted", err=True)
            rv = 1
        if not standalone_mode:
            return rv
        sys.exit(rv if isinstance(rv, int) else 0)


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
