"""The hits the fit leaves out, given their faces by the mesh: the Newton step from the truth over
fresh noise draws, with and without them.

    python -m bench.linescan.oracle_planes [--cases long-array:100:0 dish-boom:100:5] [--draws 4]
                                           [--stem NAME]

What segmenting the faces no planar surfel holds (faces seen at grazing incidence, mostly) could
gain at most. The fit's terms at the true motion, as the last stage builds them (``fit's terms``):
the surfel pairs, the thin members as lines and the grazing groups. Every kept hit none of them
holds (not in a matched planar surfel, not a member's, not in a grazing group) is given the face
of the mesh it lies on (``dense_bound.face_of_hits``: an oracle), and each face with at least
``MIN_HITS`` such hits becomes a plane of its own at ``T``, a nuisance of three parameters (offset
and two tilts) projected off its rows as ``beams.without_nuisances`` projects the members', each
hit a row

    r = n . (y - c),   var r = the sensor's variance along n,

``y`` the hit mapped to ``T``, ``n`` the face's true normal and ``c`` its hits' centroid; their
variances are scaled so that their robust scale is the surfel pairs' (as ``Terms.with_groups``
scales the grazing groups'). ``+ oracle planes`` adds every such face; ``+ oracle planes, pure cells``
only the hits whose cell holds hits of one face alone (what a segmentation that keeps cells
whole could find without the mesh). Per design the spread and bias over the dense bound's sigma
of the six rotation parameters, and the steps' RMS over the draws (``error``); the share of the
kept hits each holds. Writes JSON.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tumblescan import Scanner, Scene, random_motion
from tumblescan.linescan.dense.beams import find_beams, without_nuisances
from tumblescan.linescan.dense.data import DenseData
from tumblescan.linescan.dense.mapping import LineMapping
from tumblescan.linescan.dense.matching import CAUCHY_C, Linearized, robust_sigma
from tumblescan.linescan.dense.surfels import Surfels, normal_variance
from tumblescan.linescan.dense.terms import Terms
from tumblescan.linescan.sensor import SensorNoise, perpendiculars

from ..common import ShapeCase, draws_arguments, machine, out_dir, table
from .dense_bound import bound_covariances, face_of_hits, last_stage_matches
from .draw_bias import PARAM_NAMES, bias_table, surfel_roles
from .loss_choice import cauchy, newton_step, normalised
from .member_prism import rms
from .real_shapes import shape_named
from .reuse_diag import at_truth

DESIGNS = ("fit's terms", "+ oracle planes", "+ oracle planes, pure cells")
MIN_HITS = 30


def held_hits(surf: Surfels, terms: Terms) -> NDArray[np.bool_]:
    """Which kept hits ``(n,)`` the terms hold: in a matched planar surfel (source or target), a
    member's, or in a grazing group."""
    matched = np.zeros(len(surf.planar), dtype=bool)
    matched[terms.matches.src] = True
    matched[terms.matches.dst] = True
    held = matched[surf.point_cell]
    held[terms.beams.point] = True
    held[terms.grazing.hit] = True
    return held


def plane_rows(
    data: DenseData, mapping: LineMapping, noise: SensorNoise, hits: NDArray[np.int64], normal: NDArray[np.float64]
) -> Linearized:
    """The rows of ``hits`` (indices of kept hits, ``(k,)``) against a plane of unit normal
    ``normal`` ``(3,)`` at ``T`` through their centroid ``c``: ``r = n . (y - c)`` (m), ``y`` each
    hit mapped to ``T``, with the plane's own parameters as nuisances (its offset ``d`` and tilts
    ``a, b`` about the perpendiculars ``e1, e2``: ``dr/dd = -1``, ``dr/da = e1 . (y - c)``,
    ``dr/db = e2 . (y - c)``) projected off the residuals and their derivatives w.r.t. the
    motion ``(k, free)``; variances (m²) the sensor's along ``n``."""
    xyz, line = data.xyz_m[hits], data.line[hits]
    y = mapping.apply(xyz, line)
    c = y.mean(axis=0)
    n = np.broadcast_to(normal, y.shape)
    r = (y - c) @ normal
    n_obs = np.einsum("nji,nj->ni", mapping.Rt[line], n)
    var = normal_variance(noise, xyz, n_obs)
    e1, e2 = perpendiculars(normal[None, :])
    J_nuisance = np.column_stack([-np.ones(len(r)), (y - c) @ e1[0], (y - c) @ e2[0]])
    J = mapping.normal_derivative(np.ascontiguousarray(n), xyz, line)
    r_x, J_x = without_nuisances(J_nuisance, 1.0 / var, r, J)
    return Linearized(r_x, J_x, var)


def oracle_rows(
    data: DenseData,
    mapping: LineMapping,
    noise: SensorNoise,
    face: NDArray[np.int64],
    normals: NDArray[np.float64],
    free: NDArray[np.bool_],
) -> Linearized:
    """Every face's rows (:func:`plane_rows`) of the hits ``free`` marks ``(n,)``, faces of
    fewer than ``MIN_HITS`` such hits left out."""
    # The marked hits grouped by face in one sort (stable: each face's hits in their own order).
    marked = np.flatnonzero(free & (face >= 0))
    marked = marked[np.argsort(face[marked], kind="stable")]
    faces, first = np.unique(face[marked], return_index=True)
    parts = [
        plane_rows(data, mapping, noise, hits, normals[f])
        for f, hits in zip(faces, np.split(marked, first[1:]) if len(marked) else [], strict=True)
        if len(hits) >= MIN_HITS
    ]
    if not parts:
        return Linearized(np.zeros(0), np.zeros((0, len(mapping.free))), np.zeros(0))
    return Linearized(*(np.concatenate([getattr(p, k) for p in parts]) for k in ("r", "J", "var")))


def joined(base: Linearized, extra: Linearized, pairs: Linearized) -> Linearized:
    """``base``'s and ``extra``'s rows, ``extra``'s variances times ``(s_e / s_p)^2``, ``s_e``
    their normalised residuals' robust scale and ``s_p`` the surfel ``pairs``'."""
    if len(extra.r) == 0:
        return base
    s_b = robust_sigma(pairs.r / np.sqrt(pairs.var))
    s_e = robust_sigma(extra.r / np.sqrt(extra.var))
    scale2 = (s_e / s_b) ** 2 if s_b > 0 and s_e > 0 else 1.0
    return Linearized(
        np.concatenate([base.r, extra.r]), np.vstack([base.J, extra.J]), np.concatenate([base.var, scale2 * extra.var])
    )


@dataclass(frozen=True)
class CaseResult:
    """Per design its readings over the draws (``draw_bias.bias_table``) and the hits it holds
    (mean over the draws, share of the kept hits)."""

    readings: dict[str, dict[str, np.ndarray]]
    error_over_bound: dict[str, np.ndarray]  # the steps' RMS over the draws, per parameter
    hits_share: dict[str, float]


def case(spec: ShapeCase, draws: int) -> CaseResult:
    """Each design's bias readings over the draws (see the module)."""
    motion = random_motion(np.random.default_rng(spec.seed), distance_m=spec.distance_m)
    scene = Scene(scanner=Scanner(), shape=shape_named(spec.name))
    noise, loss = scene.scanner.noise, cauchy(CAUCHY_C)
    steps: dict[str, list[np.ndarray]] = {k: [] for k in DESIGNS}
    shares: dict[str, list[float]] = {k: [] for k in DESIGNS}
    for d in range(draws):
        sim, data, mapping, surf = at_truth(motion, scene, spec.seed + 1000 * d)
        kept = np.ones(len(sim.xyz_m), dtype=bool) if data.kept is None else data.kept
        faces, normals = face_of_hits(scene, motion, sim.reference_m)
        face = faces[kept]
        matches, pairs = last_stage_matches(data, mapping, surf, noise)
        terms = Terms(surf, matches, find_beams(data, mapping, surf, noise)).with_grazing(data, noise, mapping)
        held = held_hits(surf, terms)
        pure_cell = surfel_roles(data, surf, face).pure[surf.point_cell]
        base = terms.linearize(data, noise, mapping)
        for label, free in (
            ("fit's terms", np.zeros_like(held)),
            ("+ oracle planes", ~held),
            ("+ oracle planes, pure cells", ~held & pure_cell),
        ):
            extra = oracle_rows(data, mapping, noise, face, normals, free)
            steps[label].append(newton_step(*normalised(joined(base, extra, pairs)), loss))
            shares[label].append((held.sum() + len(extra.r)) / len(held))
    # The bound of the last draw's frames: the draws differ in their noise alone, not in the hits.
    bound_sd = np.sqrt(np.diag(bound_covariances(motion, scene, sim, float(sim.t_s.min())).facets))
    return CaseResult(
        {label: bias_table(np.array(st), bound_sd) for label, st in steps.items()},
        {label: np.sqrt(np.mean(np.square(st), axis=0)) / bound_sd for label, st in steps.items()},
        {label: float(np.mean(v)) for label, v in shares.items()},
    )


def main() -> None:
    args = draws_arguments(
        __doc__, ShapeCase("long-array", 100, 0), ShapeCase("dish-boom", 100, 5), draws=4, stem="oracle_planes"
    )
    print(machine())
    results = {}
    for spec in args.cases:
        out = case(spec, args.draws)
        results[str(spec)] = {
            "designs": {k: {q: v.tolist() for q, v in r.items()} for k, r in out.readings.items()},
            "error_over_bound": {k: v.tolist() for k, v in out.error_over_bound.items()},
            "hits_share": out.hits_share,
        }
        print(f"\n{spec}, {args.draws} draws; rotation parameters only, over the bound")
        rows = []
        for label, readings in out.readings.items():
            sd, bias = readings["sd_over_bound"][:6], readings["bias_over_bound"][:6]
            error = out.error_over_bound[label][:6]
            rows.append([label, f"{100 * out.hits_share[label]:.0f} %", f"{rms(error):.2f}", f"{rms(sd):.2f}",
                         f"{rms(bias):.2f}", *np.round(error, 2)])  # fmt: skip
        print(table(rows, ["design", "hits held", "error RMS", "spread RMS", "bias RMS", *PARAM_NAMES[:6]]))
    path = out_dir() / f"{args.stem}.json"
    path.write_text(json.dumps(results, indent=1))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
