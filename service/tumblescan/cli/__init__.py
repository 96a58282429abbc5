"""Command line: one command group per job kind, the service commands, and the line-scan
commands kept at the top level (``simulate``, ``estimate``, ``rectify``) as aliases.

Bad input exits with code 2 and one line on stderr naming the problem.
"""

from __future__ import annotations

import typer

from ..cli import linescan, service

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="Motion and position of space targets, from lidar, images and bearings.",
)
for _name, _command in (
    ("simulate", linescan.simulate),
    ("estimate", linescan.estimate),
    ("rectify", linescan.rectify),
):
    app.command(_name)(_command)
service.register(app)


def main() -> None:
    app()
