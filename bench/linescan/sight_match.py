"""Ways to match the hits the planar surfels leave out (where their line of sight meets a plane,
and others), beside the fit's own grazing groups: the Newton step from the truth over fresh
noise draws.

    python -m bench.linescan.sight_match [--cases long-array:100:14 dish-boom:100:5] [--draws 6]
                                         [--stem NAME]

The fit matches a left-out hit ``x`` at grazing incidence to the planar surfel whose anchor is
nearest it (``grazing.match_to_surfels``). Range noise moves a hit along its sight ``u``, and so
moves that match; where the sight meets a plane does not move. Here each left-out hit, in every
other frame, takes the surfel nearest it within two surfel sizes as a first plane ``(n_0, a_0)``,
the point where its sight meets that plane,

    q = x - (n_0 . (x - a_0)) / (n_0 . u) u,

and as its target the planar surfel nearest ``q`` within half a surfel size, kept when the plane
faces its sensor and ``|r| <= 3 sqrt(var_x + v_t / N_t)`` as the fit keeps its own
(:func:`match_by_sight`). The designs, each the surfel pairs of the last stage plus groups (one
per source cell and target, their variances at the pairs' robust scale, as ``Terms.with_grazing``
scales them):

- ``pairs``: no groups;
- ``grazing``: the fit's groups (``grazing.find_grazing``);
- ``grazing + members``: the fit's terms as its last stage has them, the thin members too
  (``beams.find_beams``, their hits kept off the groups);
- ``sight``: every left-out hit matched by its sight, at any incidence;
- ``grazing + steep sight``: the fit's groups, and the hits matched by their sight where the plane
  is met at ``|cos(incidence)| >= 0.3`` (a hit's grazing match in a frame kept first);
- ``grazing + grazing cells``: the fit's groups, and its candidates matched as the fit matches
  them but to the other frames' cells that hold candidates themselves (seen at grazing incidence,
  not planar, :func:`match_to_grazing_cells`): the grazing hits that no planar surfel of another
  frame holds;
- ``candidates, any incidence``: the fit's candidates matched its way, but to planes met at any
  incidence (``match_to_surfels`` with ``max_cos=None``);
- ``grazing + far steep sight``: as ``grazing + steep sight``, with the first plane within 4
  surfel sizes and the target within 1 (``FAR``): the faces' margins, where the other frames hold
  no planar surfel near the hit; the target's plane carried out to the hit with its tilt's
  variance over the lever, and only hits whose own cell's normal is within 10 deg of the target's
  (the next face's hits along an edge kept out).

As ``draw_bias.py`` does: one seeded motion of ``real_shapes``, simulated again with ``--draws``
noise seeds (``seed + 1000 d``, ``d = 0 ..``), the Cauchy cost's optimum to first order, one
Newton step from the truth; per rotation parameter, its mean over its standard error, and mean
and spread over the dense bound's sigma. Also the matched hits against the mesh (each hit's face
of the mesh and its target's majority face, ``dense_bound.face_of_hits``): the share on their
target's face and the mean offset from that face's true plane over the hit's sigma along its
normal, summed over the matches over ``sqrt(matches)`` (about 1 in size for a fair sample). And
the seconds each design's matching took (draw by draw).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from tumblescan import Motion, Scanner, Scene, random_motion
from tumblescan.linescan.dense.beams import Beams, find_beams
from tumblescan.linescan.dense.data import DenseData
from tumblescan.linescan.dense.grazing import (
    GATE_SIGMAS,
    MAX_COS_INCIDENCE,
    Grazing,
    at_reference,
    grazing_candidates,
    group_hits,
    match_to_surfels,
    other_frames,
)
from tumblescan.linescan.dense.mapping import LineMapping
from tumblescan.linescan.dense.matching import CAUCHY_C
from tumblescan.linescan.dense.surfels import Surfels, normal_variance
from tumblescan.linescan.dense.terms import Terms
from tumblescan.linescan.sensor import SensorNoise
from tumblescan.linescan.simulate import FrameCloud

from ..common import ShapeCase, draws_arguments, grouped_bars, machine, out_dir, saved_figure, table
from .dense_bound import bound_covariances, face_of_hits, last_stage_matches, majority_face
from .draw_bias import PARAM_NAMES, bias_table
from .hit_bias import true_planes
from .loss_choice import cauchy, newton_step, normalised
from .real_shapes import shape_named
from .reuse_diag import at_truth

DESIGNS = (
    "pairs",
    "grazing",
    "grazing + members",
    "sight",
    "grazing + steep sight",
    "grazing + grazing cells",
    "candidates, any incidence",
    "grazing + far steep sight",
)


@dataclass(frozen=True)
class SightReach:
    """How far (in surfel sizes) a sight's first plane and its target are looked for. ``far``:
    the target's plane is carried out to the hit (its tilt's variance over the lever in the
    gate) and only hits whose own cell's normal is within ``agree_deg`` of the target's are kept."""

    first_surfels: float = 2.0
    target_surfels: float = 0.5
    far: bool = False
    agree_deg: float = 10.0


# The faces' margins: where the other frames hold no planar surfel near the hit.
FAR = SightReach(first_surfels=4.0, target_surfels=1.0, far=True)
# The sights searched on meet their first plane at |cos(incidence)| at least this share of the
# least kept: a target's plane differs from the first's only across an edge.
PREFILTER_SHARE = 2 / 3
# A grazing cell as a target: its points, and its normal within this of the hit's own cell's.
MIN_TARGET_POINTS = 6
MAX_TARGET_ANGLE_COS = np.cos(np.radians(20.0))


def match_by_sight(
    data: DenseData,
    mapping: LineMapping,
    surf: Surfels,
    noise: SensorNoise,
    hits: np.ndarray,
    *,
    min_cos: float = 0.0,
    reach: SightReach = SightReach(),
) -> tuple[np.ndarray, np.ndarray]:
    """Each of ``hits`` (indices into the data's points) matched, in every other frame, to the
    planar surfel nearest where its sight meets a plane of that frame at ``T`` (see the module),
    kept when that plane faces the hit's sensor at ``cos(incidence) >= min_cos`` and the hit lies
    within ``GATE_SIGMAS`` of it: ``(k,)`` hits and ``(k,)`` their targets. Sights meeting their
    first plane below ``PREFILTER_SHARE * min_cos`` are not searched on (the same matches on the
    cases measured, a third less time on the dish-boom). ``reach``: how far the first plane and
    the target are looked for, and the far design's extra tests (:class:`SightReach`)."""
    x_ref, sensor_ref, anchor_ref, normal_ref = at_reference(data, mapping, surf, hits)
    sight_ref = sensor_ref - x_ref
    sight_ref /= np.maximum(np.linalg.norm(sight_ref, axis=1), 1e-300)[:, None]
    min_first = max(PREFILTER_SHARE * min_cos, 1e-3)
    found, targets = [np.zeros(0, dtype=np.int64)], [np.zeros(0, dtype=np.int64)]
    for sel, in_b in other_frames(data, surf, hits):
        tree = cKDTree(anchor_ref[in_b])
        # A first plane: the surfel nearest the hit.
        dist, nn = tree.query(x_ref[sel], k=1, distance_upper_bound=reach.first_surfels * data.surfel_m, workers=-1)
        sel, first = sel[np.isfinite(dist)], in_b[nn[np.isfinite(dist)]]
        # Where the sight meets it: a point the hit's range noise does not move.
        u = sight_ref[sel]
        cos0 = np.einsum("ni,ni->n", normal_ref[first], u)
        steep = np.abs(cos0) >= min_first
        sel, first, u, cos0 = sel[steep], first[steep], u[steep], cos0[steep]
        r0 = np.einsum("ni,ni->n", normal_ref[first], x_ref[sel] - anchor_ref[first])
        q = x_ref[sel] - (r0 / cos0)[:, None] * u
        # The target: the surfel nearest that point.
        dist, nn = tree.query(q, k=1, distance_upper_bound=reach.target_surfels * data.surfel_m, workers=-1)
        ok = np.isfinite(dist)
        sel, t, u = sel[ok], in_b[nn[ok]], u[ok]
        n = normal_ref[t]
        d = x_ref[sel] - anchor_ref[t]
        r = np.einsum("ni,ni->n", n, d)
        cos = np.einsum("ni,ni->n", n, u)
        h = hits[sel]
        var = normal_variance(noise, data.xyz_m[h], np.einsum("nji,nj->ni", mapping.Rt[data.line[h]], n))
        var += surf.var_m2[t] / surf.count[t]
        keep = (cos > 0) & (cos >= min_cos)
        if reach.far:
            # The target's plane carried out to the hit: its tilt's variance over the lever (as
            # the groups' rows carry it), and the hit's own cell of the target's direction, which
            # keeps out the hits of the next face along an edge.
            var += (np.einsum("ni,ni->n", d, d) - r**2) * surf.normal_var_rad2[t]
            own = normal_ref[data.cell[h]]
            keep &= np.abs(np.einsum("ni,ni->n", own, n)) > np.cos(np.radians(reach.agree_deg))
        keep &= r**2 <= GATE_SIGMAS**2 * var
        found.append(h[keep])
        targets.append(t[keep])
    return np.concatenate(found), np.concatenate(targets)


def design_groups(
    data: DenseData, mapping: LineMapping, surf: Surfels, noise: SensorNoise, beams: Beams
) -> tuple[dict[str, tuple[Grazing, np.ndarray, np.ndarray]], dict[str, float]]:
    """Each design's groups (see the module) and the hits and targets they were made of; the
    seconds the fit's grazing matching and each timed design's own matching took (a combined
    design's time is its own matcher's, beyond the grazing matching it starts from)."""
    seconds: dict[str, float] = {}
    left_out = np.flatnonzero(~surf.planar[surf.point_cell])
    every_hit, every_target = match_by_sight(data, mapping, surf, noise, left_out)
    # The fit's own: its candidates, matched its way (``find_grazing``'s groups).
    start = time.perf_counter()
    candidates = grazing_candidates(data, surf)
    g_hit, g_target = match_to_surfels(data, mapping, surf, noise, candidates)
    seconds["grazing"] = time.perf_counter() - start
    # The fit's as its last stage has them: the members' hits kept off the groups.
    m_hit, m_target = match_to_surfels(data, mapping, surf, noise, grazing_candidates(data, surf, exclude=beams.point))
    start = time.perf_counter()
    s_hit, s_target = match_by_sight(data, mapping, surf, noise, left_out, min_cos=MAX_COS_INCIDENCE)
    seconds["grazing + steep sight"] = time.perf_counter() - start
    start = time.perf_counter()
    f_hit, f_target = match_by_sight(data, mapping, surf, noise, left_out, min_cos=MAX_COS_INCIDENCE, reach=FAR)
    seconds["grazing + far steep sight"] = time.perf_counter() - start
    start = time.perf_counter()
    c_hit, c_target = match_to_grazing_cells(data, mapping, surf, noise, candidates)
    seconds["grazing + grazing cells"] = time.perf_counter() - start
    a_hit, a_target = match_to_surfels(data, mapping, surf, noise, candidates, max_cos=None)
    both = {
        "candidates, any incidence": (a_hit, a_target),
        "grazing + steep sight": _first_kept(data, g_hit, g_target, s_hit, s_target),
        "grazing + far steep sight": _first_kept(data, g_hit, g_target, f_hit, f_target),
        "grazing + grazing cells": _first_kept(data, g_hit, g_target, c_hit, c_target),
    }
    empty = np.zeros(0, dtype=np.int64)
    out = {
        "pairs": (Grazing.none(), empty, empty),
        "grazing": (group_hits(data, mapping, surf, g_hit, g_target), g_hit, g_target),
        "grazing + members": (group_hits(data, mapping, surf, m_hit, m_target), m_hit, m_target),
        "sight": (group_hits(data, mapping, surf, every_hit, every_target), every_hit, every_target),
    }
    for label, (hit, target) in both.items():
        out[label] = (group_hits(data, mapping, surf, hit, target), hit, target)
    return out, seconds


def match_to_grazing_cells(
    data: DenseData, mapping: LineMapping, surf: Surfels, noise: SensorNoise, hits: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Each of ``hits`` (grazing candidates) matched, in every other frame, to the nearest cell
    of that frame that holds candidates itself (whole, not planar, seen at grazing incidence)
    within a surfel size at ``T``, whose normal agrees with the hit's own cell's within 20 deg,
    kept as ``match_to_surfels`` keeps its matches at any incidence (facing, in-plane, gate)."""
    is_target = np.zeros(len(surf.planar), dtype=bool)
    is_target[data.cell[hits]] = True
    is_target &= surf.count >= MIN_TARGET_POINTS
    # The candidates' cells stand in for the planar surfels as targets.
    hit, target = match_to_surfels(data, mapping, replace(surf, planar=is_target), noise, hits, max_cos=None)
    normal_ref = mapping.rotate(surf.normal_obs, surf.line)
    agree = np.abs(np.einsum("ni,ni->n", normal_ref[target], normal_ref[data.cell[hit]])) > MAX_TARGET_ANGLE_COS
    return hit[agree], target[agree]


def _first_kept(
    data: DenseData, g_hit: np.ndarray, g_target: np.ndarray, s_hit: np.ndarray, s_target: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The grazing matches, then the sight's matches of (hit, frame) pairs they do not hold."""
    fresh = ~np.isin(
        s_hit * data.n_frames + data.cell_frame[s_target], g_hit * data.n_frames + data.cell_frame[g_target]
    )
    return np.concatenate([g_hit, s_hit[fresh]]), np.concatenate([g_target, s_target[fresh]])


def mesh_truth(
    scene: Scene, motion: Motion, sim: FrameCloud, data: DenseData, mapping: LineMapping, surf: Surfels
) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """What :func:`against_mesh` judges by: each kept hit's face of the mesh ``(n,)`` (-1: none),
    each surfel's majority face ``(m,)`` and the faces' true planes at ``T``."""
    kept = np.ones(len(sim.xyz_m), dtype=bool) if data.kept is None else data.kept
    face = face_of_hits(scene, motion, sim.reference_m)[0][kept]
    points_T = mapping.apply(sim.xyz_true_m[kept], data.line)
    planes = true_planes(face, points_T, mapping.apply(np.zeros_like(points_T), data.line))
    return face, majority_face(surf.point_cell, face, len(surf.planar)), planes


def against_mesh(
    hit: np.ndarray,
    target: np.ndarray,
    face: np.ndarray,
    surf_face: np.ndarray,
    data: DenseData,
    mapping: LineMapping,
    noise: SensorNoise,
    planes: tuple[np.ndarray, np.ndarray],
) -> tuple[float, float]:
    """The share of the matches whose hit lies on its target's face, and the matches' offsets from
    that face's true plane over their sigmas, summed over ``sqrt(matches)``."""
    if len(hit) == 0:
        return float("nan"), float("nan")
    normals, offsets = planes
    f = np.maximum(surf_face[target], 0)
    n = normals[f]
    x = mapping.apply(data.xyz_m[hit], data.line[hit])
    var = normal_variance(noise, data.xyz_m[hit], np.einsum("nji,nj->ni", mapping.Rt[data.line[hit]], n))
    z = (np.einsum("ni,ni->n", n, x) - offsets[f]) / np.sqrt(var)
    same = (face[hit] >= 0) & (face[hit] == surf_face[target])
    return float(same.mean()), float(z.sum() / np.sqrt(len(z)))


def case(spec: ShapeCase, draws: int) -> dict[str, dict[str, list[float]]]:
    """Each design's bias readings over the draws, and its matches against the mesh (first draw)."""
    motion = random_motion(np.random.default_rng(spec.seed), distance_m=spec.distance_m)
    scene = Scene(scanner=Scanner(), shape=shape_named(spec.name))
    noise, loss = scene.scanner.noise, cauchy(CAUCHY_C)
    steps: dict[str, list[np.ndarray]] = {k: [] for k in DESIGNS}
    out: dict[str, dict[str, list[float]]] = {}
    for d in range(draws):
        sim, data, mapping, surf = at_truth(motion, scene, spec.seed + 1000 * d)
        matches, _ = last_stage_matches(data, mapping, surf, noise)
        beams = find_beams(data, mapping, surf, noise)
        designs, seconds = design_groups(data, mapping, surf, noise, beams)
        print(f"draw {d}: matching seconds " + ", ".join(f"{k} {v:.2f}" for k, v in seconds.items()), flush=True)
        if d == 0:
            face, surf_face, planes = mesh_truth(scene, motion, sim, data, mapping, surf)
            for label, (groups, hit, target) in designs.items():
                share, z_sum = against_mesh(hit, target, face, surf_face, data, mapping, noise, planes)
                out[label] = {"hits": [float(groups.hits)], "on_target_face": [share], "offset_sum": [z_sum]}
        for label, (groups, _, _) in designs.items():
            pairs = Terms(surf, matches, beams if label == "grazing + members" else Beams.none())
            lin = pairs.with_groups(groups, data, noise, mapping).linearize(data, noise, mapping)
            steps[label].append(newton_step(*normalised(lin), loss))
    bound_sd = np.sqrt(np.diag(bound_covariances(motion, scene, sim, float(sim.t_s.min())).facets))
    for label, st in steps.items():
        out[label].update({q: v.tolist() for q, v in bias_table(np.array(st), bound_sd).items()})
    return out


def main() -> None:
    args = draws_arguments(
        __doc__, ShapeCase("long-array", 100, 14), ShapeCase("dish-boom", 100, 5), draws=6, stem="sight_match"
    )
    print(machine())
    results = {}
    for spec in args.cases:
        results[str(spec)] = out = case(spec, args.draws)
        print(f"\n{spec}, {args.draws} draws; rotation parameters only")
        rows = [
            [label, f"{r['hits'][0]:.0f}", f"{r['on_target_face'][0]:.3f}", f"{r['offset_sum'][0]:+.2f}"]
            for label, r in out.items()
        ]
        print(table(rows, ["design", "hits (draw 0)", "on the target's face", "offset sum / sqrt(matches)"]))
        rows = [
            [label, quantity, *np.round(readings[quantity][:6], 2)]
            for label, readings in out.items()
            for quantity in ("bias_over_se", "bias_over_bound", "sd_over_bound")
        ]
        print(table(rows, ["design", "per parameter", *PARAM_NAMES[:6]]))
    path = out_dir() / f"{args.stem}.json"
    path.write_text(json.dumps(results, indent=1))
    _plot(results, path.with_suffix(".png"))
    print(f"wrote {path} and .png")


def _plot(results: dict[str, dict[str, dict[str, list[float]]]], path: Path) -> None:
    """Per case and design, the RMS over the rotation parameters of the bias and of the spread,
    both over the bound: what a design moves the estimate by, and how much it scatters."""
    cases = list(results)

    def rms(case: str, design: str, quantity: str) -> float:
        return float(np.sqrt(np.mean(np.square(results[case][design][quantity][:6]))))

    series = {
        f"{d}: {word}": [rms(c, d, quantity) for c in cases]
        for d in DESIGNS
        for word, quantity in (("spread", "sd_over_bound"), ("bias", "bias_over_bound"))
    }
    with saved_figure(
        path, title="Newton step from the truth, by design", ylabel="RMS over the bound", legend_columns=2
    ) as ax:
        grouped_bars(ax, cases, series)


if __name__ == "__main__":
    main()
