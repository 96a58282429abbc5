"""Is a miss the fit's own optimum, or a failure to reach it? The whole estimate beside the
dense fit refined from the true motion on the same frames.

    python -m bench.linescan.from_truth hubble:50:2 long-array:50:2 [...] [--size 512]

Each case ``shape:range_m:seed`` is the real-shapes bench's (``real_shapes.one``: its seeded
motion and frames). Per case, each parameter's error over the dense bound (``dense_bound.py``)
for: the whole estimate (registration, starts, refinement, model choice); the last stage of the
refinement from the true motion (every surfel matched in every other frame, the tightest gate);
all three stages from the true motion. When the refinements from the truth land where the whole
estimate did, its error is the optimum's (noise or a bias of the surfel model), and a better
search would not remove it.
"""

from __future__ import annotations

import argparse

import numpy as np

from tumblescan import Scanner, Scene, random_motion
from tumblescan.linescan.dense.refine import refine_dense
from tumblescan.target.motion import canonical_params

from ..common import shape_case, table
from .bias_map import in_bounds
from .real_shapes import PARAMS, UNITS, estimated, shape_named
from .truth import frames_at_truth


def case(name: str, distance_m: float, seed: int, size: int) -> list[list[object]]:
    """Rows ``[case, variant, error / bound per parameter...]`` for one bench case."""
    motion = random_motion(np.random.default_rng(seed), distance_m=distance_m)
    scene = Scene(scanner=Scanner(lines=size, pixels=size), shape=shape_named(name))
    # The bench's frames (noise seed = motion seed) and their dense data at T, the first point's
    # time: the estimate's default reference time, so both are stated at the same T.
    sim, data, mapping = frames_at_truth(motion, scene, seed)
    whole = estimated(name, distance_m, seed, motion, scene, sim)
    label = f"{name} {distance_m:g} m seed {seed}"
    rows: list[list[object]] = [
        [
            label,
            "whole estimate",
            *(f"{whole.errors[f'{p}_{UNITS[p]}'] / whole.bound[f'{p}_{UNITS[p]}']:.2f}" for p in PARAMS),
        ]
    ]
    x_true = canonical_params(mapping.x)
    for variant, converged in (("last stage from the truth", True), ("all stages from the truth", False)):
        fit = refine_dense(data, mapping.x, noise=scene.scanner.noise, converged=converged)
        rows.append([label, variant, *(f"{v:.2f}" for v in in_bounds(x_true, fit.x - x_true, whole.bound))])
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("cases", nargs="+", type=shape_case, help="shape:range_m:seed, e.g. hubble:50:2")
    parser.add_argument("--size", type=int, default=512, help="lines and pixels per frame")
    args = parser.parse_args()
    rows: list[list[object]] = []
    for name, distance, seed in args.cases:
        rows += case(name, distance, seed, args.size)
    print("error / dense bound per parameter")
    print(table(rows, ["case", "fit", *PARAMS]))


if __name__ == "__main__":
    main()
