"""Bias and spread of the surfel pairs' optimum over fresh noise draws of one motion, by which
surfels the pairs join.

    python -m bench.linescan.draw_bias [--cases box:50:14 long-array:100:31] [--draws 8]
                                       [--variant no-handover|...] [--stem NAME]

One case's error from the truth mixes a bias (the same in every noise draw) with noise; the
real-shapes bench's cases have one draw each, so its RMS over cases cannot tell them apart.
Here one seeded motion of ``real_shapes`` is simulated again with ``--draws`` fresh noise seeds
(``seed + 1000 d``, ``d = 1 .. draws``: the bench's own draw, ``d = 0``, is left out, since a case
picked for its large error would carry that error into the mean). At the true motion, as
``loss_choice.py`` does: the surfels and the last stage's matches as the refinement builds them,
and the Cauchy cost's optimum to first order, one Newton step from the truth. Over the draws,
per parameter of the 9-vector: the mean step over its standard error (``bias / SE``; about 1
when there is none), and the mean and the spread over the dense bound's sigma.

The pairs are read whole and by subset, each subset a Newton step of its own:

- ``pure``: both surfels' points all on one face of the mesh (``dense_bound.face_of_hits``);
- ``interior``: both surfels pure and their 8 view neighbours too, on the same face (away from
  every edge and outline);
- ``no receivers``: neither surfel took points from a cell across an edge
  (``handover.assign_to_faces``);
- ``all + left-out``: all pairs and the left-out hits' groups as the last stage adds them
  (``grazing.find_grazing``, their variances at the pairs' robust scale; no thin members).

``--variant``: the surfels built as ``bias_map.py``'s variant of that name (``no-handover``: every
point kept in its own cell). With ``noise-free-anchors`` (each anchor less its points' mean
noise) a step is the first-order bias of the surfels' geometry (their points, normals and
partners) in that draw, with a spread of its own far below the noise's: the pairs are weighed at
the measured anchors' robust scale (:func:`measured_scale`), and ``all + left-out`` is not read
(the groups' hits keep their noise).
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from tumblescan import Scanner, Scene, random_motion
from tumblescan.linescan.dense.beams import Beams
from tumblescan.linescan.dense.data import DenseData
from tumblescan.linescan.dense.mapping import LineMapping
from tumblescan.linescan.dense.matching import CAUCHY_C, Matches, linearize
from tumblescan.linescan.dense.surfels import Surfels
from tumblescan.linescan.dense.terms import Terms
from tumblescan.linescan.sensor import SensorNoise
from tumblescan.linescan.simulate import FrameCloud

from ..common import ShapeCase, add_cases, machine, out_dir, table
from .bias_map import VARIANTS, anchor_noise_m, variant_surfels
from .dense_bound import bound_covariances, face_of_hits, last_stage_matches
from .loss_choice import cauchy, newton_step, normalised
from .real_shapes import shape_named

SUBSETS = ("all", "pure", "interior", "no receivers", "all + left-out")
PARAM_NAMES = ("spin az", "spin pol", "spin rate", "prec az", "prec pol", "prec rate", "cx", "cy", "cz")


@dataclass(frozen=True)
class SurfelRoles:
    """Per surfel ``(m,)``: all its points on one face of the mesh (``pure``), pure with its 8 view
    neighbours pure on the same face (``interior``), and holding points of another cell
    (``receiver``: the hand-over gave it some)."""

    pure: NDArray[np.bool_]
    interior: NDArray[np.bool_]
    receiver: NDArray[np.bool_]


def surfel_roles(data: DenseData, surf: Surfels, face: NDArray[np.int64]) -> SurfelRoles:
    """The roles of the surfels from each kept hit's face (``-1``: on none)."""
    pc, m = surf.point_cell, len(surf.planar)
    lowest = np.full(m, np.iinfo(np.int64).max)
    highest = np.full(m, -2, dtype=np.int64)
    np.minimum.at(lowest, pc, face)
    np.maximum.at(highest, pc, face)
    pure = (lowest == highest) & (lowest >= 0)
    nb = data.neighbours
    safe = np.maximum(nb, 0)
    interior = pure & np.all(nb >= 0, axis=1) & np.all(pure[safe] & (lowest[safe] == lowest[:, None]), axis=1)
    receiver = np.zeros(m, dtype=bool)
    receiver[pc[pc != data.cell]] = True
    return SurfelRoles(pure, interior, receiver)


def subset_rows(roles: SurfelRoles, matches: Matches) -> dict[str, NDArray[np.bool_]]:
    """Which pairs each subset keeps: both their surfels in the role (none a receiver)."""
    s, t = matches.src, matches.dst
    return {
        "all": np.ones(len(s), dtype=bool),
        "pure": roles.pure[s] & roles.pure[t],
        "interior": roles.interior[s] & roles.interior[t],
        "no receivers": ~roles.receiver[s] & ~roles.receiver[t],
    }


def bias_table(steps: np.ndarray, bound_sd: np.ndarray) -> dict[str, np.ndarray]:
    """Of the steps ``(draws, 9)`` from the truth: mean over its standard error, and mean and
    spread (sample sd) over the bound's sigmas ``(9,)``."""
    mean, sd = steps.mean(axis=0), steps.std(axis=0, ddof=1)
    return {
        "bias_over_se": mean / (sd / np.sqrt(len(steps))),
        "bias_over_bound": mean / bound_sd,
        "sd_over_bound": sd / bound_sd,
    }


def case(
    name: str, distance_m: float, seed: int, draws: int, size: int, variant: str = "none"
) -> dict[str, dict[str, list[float]]]:
    """The bias readings of each subset (see the module) for one motion of ``real_shapes``."""
    motion = random_motion(np.random.default_rng(seed), distance_m=distance_m)
    scene = Scene(scanner=Scanner(lines=size, pixels=size), shape=shape_named(name))
    loss = cauchy(CAUCHY_C)
    steps: dict[str, list[np.ndarray]] = {k: [] for k in SUBSETS}
    for d in range(1, draws + 1):
        sim, data, mapping, surf = variant_surfels(variant, motion, scene, seed + 1000 * d)
        kept = np.ones(len(sim.xyz_m), dtype=bool) if data.kept is None else data.kept
        face = face_of_hits(scene, motion, sim.reference_m)[0][kept]
        matches, lin = last_stage_matches(data, mapping, surf, scene.scanner.noise)
        e, s, Jn = normalised(lin)
        if variant == "noise-free-anchors":
            s = measured_scale(sim, data, mapping, surf, matches, scene.scanner.noise)
        for label, rows in subset_rows(surfel_roles(data, surf, face), matches).items():
            steps[label].append(newton_step(e[rows], s, Jn[rows], loss))
        if variant == "noise-free-anchors":
            continue  # the groups' hits keep their noise, and their variances follow the pairs' scale
        terms = Terms(surf, matches, Beams.none()).with_grazing(data, scene.scanner.noise, mapping)
        steps["all + left-out"].append(
            newton_step(*normalised(terms.linearize(data, scene.scanner.noise, mapping)), loss)
        )
    bound_sd = np.sqrt(np.diag(bound_covariances(motion, scene, sim, float(sim.t_s.min())).facets))
    return {k: {q: v.tolist() for q, v in bias_table(np.array(st), bound_sd).items()} for k, st in steps.items() if st}


def measured_scale(
    sim: FrameCloud, data: DenseData, mapping: LineMapping, clean: Surfels, matches: Matches, noise: SensorNoise
) -> float:
    """The robust scale of the pairs' normalised residuals with the anchors as measured, for
    ``clean`` surfels whose anchors had their noise taken out (``bias_map``'s variant). Their
    residuals are the surfels' misfit alone, which the fit weighs at the noise's scale: at their
    own, far smaller scale the Cauchy loss would take the misfit for outliers and understate it."""
    measured = replace(clean, anchor_obs=clean.anchor_obs + anchor_noise_m(sim, data, clean))
    return normalised(linearize(data, mapping, measured, matches, noise))[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_cases(parser, ShapeCase("box", 50, 14), ShapeCase("long-array", 100, 31))
    parser.add_argument("--draws", type=int, default=8)
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--variant", choices=VARIANTS, default="none", help="the surfels as bias_map's variant")
    parser.add_argument("--stem", default="draw_bias")
    args = parser.parse_args()
    print(machine())
    results = {}
    for spec in args.cases:
        results[str(spec)] = out = case(spec.name, spec.distance_m, spec.seed, args.draws, args.size, args.variant)
        print(f"\n{spec}, {args.draws} draws, surfels: {args.variant}")
        rows = [
            [label, quantity, *np.round(values, 2)]
            for label, readings in out.items()
            for quantity, values in readings.items()
        ]
        print(table(rows, ["pairs", "per parameter", *PARAM_NAMES]))
    path = out_dir() / f"{args.stem}.json"
    path.write_text(json.dumps(results, indent=1))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
