"""Command line: one command group per job kind (named as the kind), the service commands,
and the line-scan commands kept at the top level (``simulate``, ``estimate``, ``rectify``) as
aliases of ``tumblescan linescan-motion ...``.

Bad input exits with code 2 and one line on stderr naming the problem.
"""

from __future__ import annotations

import typer

from . import bearings, demo, linescan, marker_pose, panel_axis, remote, service, spin_rate
from .common import OneLineErrors

app = typer.Typer(
    cls=OneLineErrors,
    add_completion=False,
    no_args_is_help=True,
    help="How space targets move and where they are: line-scan lidar, images, markers, bearings.",
)

# One group per kind, named as the kind (one line per kind, as in jobs/registry.py).
KIND_GROUPS: list[tuple[str, typer.Typer]] = [
    ("linescan-motion", linescan.app),
    ("panel-axis", panel_axis.app),
    ("marker-pose-graph", marker_pose.app),
    ("bearings", bearings.app),
    ("spin-from-images", spin_rate.app),
]
for _name, _group in KIND_GROUPS:
    app.add_typer(_group, name=_name)

# Before the kinds came, the line-scan commands were the top level; they still are.
for _command in (linescan.simulate, linescan.estimate, linescan.rectify):
    app.command(help=f"{_command.__doc__}\n\nAlias of 'tumblescan linescan-motion {_command.__name__}'.")(_command)
service.register(app)
remote.register(app)
app.command()(demo.demo)


def main() -> None:
    app()
