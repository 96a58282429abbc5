"""Shared helpers for the benchmarks: scenarios on the paper's grid, tables, output folder."""

from __future__ import annotations

import argparse
import os
import platform
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from tumblescan import Motion, Scene, Tracks, random_motion, simulate_tracks

OUT = Path(__file__).resolve().parent / "out"


def out_dir() -> Path:
    OUT.mkdir(parents=True, exist_ok=True)
    return OUT


def scenario(seed: int, *, noise: bool, scene: Scene | None = None) -> tuple[Motion, Tracks]:
    """Motion on the paper's grid (w_s 15-37, w_p 3-14 deg/s, random axes) and its tracks."""
    motion = random_motion(np.random.default_rng(seed))
    tracks, _ = simulate_tracks(motion, scene or Scene(noise=noise), seed=seed)
    return motion, tracks


class ShapeCase(NamedTuple):
    """One case of the line-scan benches on real shapes: a shape of ``bench.linescan.real_shapes``,
    its range (m) and the motion's seed; ``str()`` gives it back as ``shape:range_m:seed``."""

    name: str
    distance_m: float
    seed: int

    def __str__(self) -> str:
        return f"{self.name}:{self.distance_m:g}:{self.seed}"


def shape_case(spec: str) -> ShapeCase:
    """``shape:range_m:seed`` (``hubble:50:2``) as a :class:`ShapeCase`; an argparse ``type``, so
    a malformed one is a usage error naming it."""
    try:
        name, distance, seed = spec.split(":")
        return ShapeCase(name, float(distance), int(seed))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{spec!r} is not shape:range_m:seed (e.g. hubble:50:2)") from None


def add_cases(parser: argparse.ArgumentParser, *default: ShapeCase) -> None:
    """A ``--cases shape:range_m:seed ...`` option (:func:`shape_case`), ``default`` when not given."""
    parser.add_argument("--cases", nargs="+", type=shape_case, default=list(default), help="shape:range_m:seed")


def draws_arguments(doc: str | None, *default: ShapeCase, draws: int, stem: str) -> argparse.Namespace:
    """The command line of a bench that reads seeded cases over fresh noise draws: ``--cases``
    (``default``), ``--draws`` and ``--stem`` (the name of its outputs in ``bench/out``)."""
    parser = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_cases(parser, *default)
    parser.add_argument("--draws", type=int, default=draws, help="noise draws per case")
    parser.add_argument("--stem", default=stem)
    return parser.parse_args()


def table(rows: Sequence[Sequence[object]], header: Sequence[str]) -> str:
    cells = [[str(h) for h in header]] + [[_fmt(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    lines = ["  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def grouped_bars(
    ax: Any, groups: Sequence[str], series: Mapping[str, Sequence[float]], *, hatched: str | None = None
) -> dict[str, np.ndarray]:
    """Each series' bars side by side over the ``groups`` on a matplotlib axis, ticked with the
    groups' names (the series named ``hatched``, if any, hatched); each series' bar positions."""
    width = 0.8 / len(series)
    at = {}
    for i, (label, values) in enumerate(series.items()):
        at[label] = np.arange(len(groups)) + (i - (len(series) - 1) / 2) * width
        ax.bar(at[label], values, width, label=label, hatch="//" if label == hatched else None)
    ax.set_xticks(np.arange(len(groups)), groups)
    return at


@contextmanager
def saved_figure(
    path: Path, *, title: str, ylabel: str, size: tuple[float, float] = (9, 4.5), legend_columns: int = 1
) -> Iterator[Any]:
    """A matplotlib axis to draw on (off screen), titled, labelled, with its legend, and saved
    to ``path`` when the block ends."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=size)
    try:
        yield ax
        ax.set_ylabel(ylabel)
        ax.set_title(title)
        ax.legend(fontsize=7, ncol=legend_columns)
        fig.tight_layout()
        fig.savefig(path, dpi=120)
    finally:
        plt.close(fig)


def machine() -> str:
    return f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"


def _fmt(c: object) -> str:
    if isinstance(c, float):
        return f"{c:.3g}"
    return str(c)
