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

from tumblescan import Scanner, Scene, TimedCloud, estimate_from_frames, random_motion, simulate_frames
from tumblescan.linescan.dense.estimate import SURFEL_FRACTION
from tumblescan.linescan.dense.refine import refine_dense
from tumblescan.linescan.dense.registration import extent_m
from tumblescan.linescan.dense.surfels import prepare
from tumblescan.linescan.frames import assemble_frames
from tumblescan.target.motion import canonical_params

from ..common import table
from .bias_map import in_bounds
from .dense import errors
from .real_shapes import PARAMS, UNITS, against_bound, shape_named


def case(name: str, distance_m: float, seed: int, size: int) -> list[list[object]]:
    """Rows ``[case, variant, error / bound per parameter...]`` for one bench case."""
    motion = random_motion(np.random.default_rng(seed), distance_m=distance_m)
    scene = Scene(scanner=Scanner(lines=size, pixels=size), shape=shape_named(name))
    sim = simulate_frames(motion, scene, seed=seed)
    frames = assemble_frames(TimedCloud(sim.xyz_m, sim.t_s, {"frame": sim.frame, "line": sim.line}))
    result = estimate_from_frames(frames)
    e = errors(result, motion)
    bound = against_bound(motion, scene, sim, result.reference_time_s, e)["bound"]
    label = f"{name} {distance_m:g} m seed {seed}"
    rows: list[list[object]] = [
        [label, "whole estimate", *(f"{e[f'{p}_{UNITS[p]}'] / bound[f'{p}_{UNITS[p]}']:.2f}" for p in PARAMS)]
    ]
    # The dense data as the estimator prepares it, at the estimate's reference time.
    T = result.reference_time_s
    frame = sim.frame.astype(np.int64)
    per_frame = [sim.xyz_m[frame == f] for f in range(int(frame.max()) + 1)]
    data = prepare(sim.xyz_m, sim.t_s - T, frame, surfel_m=extent_m(per_frame) * SURFEL_FRACTION,
                   range_sigma_m=scene.scanner.noise.range_sigma_m)  # fmt: skip
    x_true = motion.at_reference(T).params()
    for variant, converged in (("last stage from the truth", True), ("all stages from the truth", False)):
        fit = refine_dense(data, x_true, noise=scene.scanner.noise, converged=converged)
        x_ref = canonical_params(x_true)
        ratio = in_bounds(x_ref, fit.x - x_ref, bound)
        rows.append([label, variant, *(f"{v:.2f}" for v in ratio)])
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("cases", nargs="+", help="shape:range_m:seed, e.g. hubble:50:2")
    parser.add_argument("--size", type=int, default=512, help="lines and pixels per frame")
    args = parser.parse_args()
    rows: list[list[object]] = []
    for spec in args.cases:
        name, distance, seed = spec.split(":")
        rows += case(name, float(distance), int(seed), args.size)
    print("error / dense bound per parameter")
    print(table(rows, ["case", "fit", *PARAMS]))


if __name__ == "__main__":
    main()
