"""Thin members as square prisms beside the fit's lines: the Newton step from the truth over fresh
noise draws.

    python -m bench.linescan.member_prism [--cases dish-boom:100:5 dish-boom:50:2] [--draws 4]
                                          [--stem NAME]

The fit models a member as a line (``beams.py``): each hit's offsets across it and along the
sight, with the variances of what the pixels see of its section, so a 10 cm square section counts
as noise. The dense bound gives each hit of a member its face of the mesh at the sensor's noise
(``used_bound.py``: on the dish-boom the boom's hits take the bound of the planar surfels' hits
from 1.7-1.9 to 1.3). Here a member's hits at ``T`` are held against a square prism: its line
``c + s d``, its roll ``psi`` about it and its half-width ``h``, each hit against the face its
section coordinates put it on,

    r = n . (y - c) - h,   var r = the sensor's variance along n,

``n`` that face's outward normal (:func:`fit_prism`: a start from the hits' line and the roll
whose square fits their section best, :func:`roll_and_half_width`, then ``PRISM_STEPS`` Gauss-Newton
steps in the prism's own parameters, since the hits' centre lies off the axis towards the faces
the sensor sees). Hits within ``CORNER_SIGMAS`` of a corner's diagonal are left out (their face
is the noise's to choose), and those beyond ``GATE_SIGMAS`` (another part's). The line, roll and
half-width are nuisances, projected off the rows as ``beams.beam_rows`` projects its own.

The designs, each the surfel pairs of the last stage and the grazing groups (the members' hits
kept off them), as ``sight_match.py`` builds them: ``no members``; ``line members`` (the fit's);
``lines, sensor variances`` (the line's rows at the sensor's variances, no wobble's shrink: what
the section costs it); ``prism members``. Per design the spread and bias over the dense bound's
sigma of the six rotation parameters; per member (first draw) its hits, those the prism keeps,
its half-width and its residuals' RMS over their sigmas. Writes JSON.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, replace

import numpy as np

from tumblescan import Scanner, Scene, random_motion
from tumblescan.linescan.dense.beams import Beams, find_beams, without_nuisances
from tumblescan.linescan.dense.data import DenseData
from tumblescan.linescan.dense.grazing import find_grazing
from tumblescan.linescan.dense.mapping import LineMapping
from tumblescan.linescan.dense.matching import CAUCHY_C, Linearized
from tumblescan.linescan.dense.members import fit_line
from tumblescan.linescan.dense.surfels import normal_variance
from tumblescan.linescan.dense.terms import Terms
from tumblescan.linescan.sensor import SensorNoise, perpendiculars

from ..common import ShapeCase, draws_arguments, machine, out_dir, table
from .dense_bound import bound_covariances, last_stage_matches
from .draw_bias import PARAM_NAMES, bias_table
from .loss_choice import cauchy, newton_step, normalised
from .real_shapes import shape_named
from .reuse_diag import at_truth

DESIGNS = ("no members", "line members", "lines, sensor variances", "prism members")
CORNER_SIGMAS = 1.5
GATE_SIGMAS = 4.0
ROLL_STEP_DEG = 0.5
PRISM_STEPS = 4


@dataclass(frozen=True)
class PrismFit:
    """One member's prism: its hits, those kept, its half-width (m) and the kept residuals' RMS
    over their sigmas."""

    hits: int
    kept: int
    half_width_m: float
    rms_sigmas: float


def roll_and_half_width(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """The roll ``psi`` (rad, in [0, pi/2)) and half-width ``h`` of the square whose boundary the
    section coordinates ``(a, b)`` (m) lie nearest: on it, ``max(|a'|, |b'|) = h`` in the square's
    own axes; the roll whose values of that spread least (median absolute deviation)."""
    best = (np.inf, 0.0, 0.0)
    for psi in np.radians(np.arange(0.0, 90.0, ROLL_STEP_DEG)):
        linf = np.maximum(np.abs(np.cos(psi) * a + np.sin(psi) * b), np.abs(-np.sin(psi) * a + np.cos(psi) * b))
        h = float(np.median(linf))
        score = float(np.median(np.abs(linf - h)))
        if score < best[0]:
            best = (score, float(psi), h)
    return best[1], best[2]


@dataclass(frozen=True)
class Prism:
    """One member's prism at ``T``: the hits kept (positions among its hits), their residuals (m),
    faces' unit normals ``(k, 3)``, sensor variances (m²) and derivatives w.r.t. the nuisances
    ``(k, 6)``; its half-width (m)."""

    kept: np.ndarray
    r: np.ndarray
    normal: np.ndarray
    var: np.ndarray
    J_nuisance: np.ndarray
    half_width_m: float


def fit_prism(
    y: np.ndarray, xyz: np.ndarray, line: np.ndarray, mapping: LineMapping, noise: SensorNoise
) -> Prism | None:
    """The square prism of one member's hits ``y`` at ``T`` ``(n, 3)`` (observed ``xyz`` on
    ``line``): a start from the hits' line and :func:`roll_and_half_width`, then Gauss-Newton steps
    in the nuisances (the centre, seen from the faces the sensor sees, starts off the axis), each
    hit against the face its section coordinates put it on; None with fewer than 10 hits kept."""
    c, d = fit_line(y, np.ones(len(y)))
    e1, e2 = (e[0] for e in perpendiculars(d[None, :]))
    psi, h = roll_and_half_width((y - c) @ e1, (y - c) @ e2)
    f1 = np.cos(psi) * e1 + np.sin(psi) * e2
    for step in range(PRISM_STEPS + 1):
        f2 = np.cross(d, f1)
        v = y - c
        a, b = v @ f1, v @ f2
        n = np.where((np.abs(a) >= np.abs(b))[:, None], np.sign(a)[:, None] * f1, np.sign(b)[:, None] * f2)
        var = normal_variance(noise, xyz, np.einsum("nji,nj->ni", mapping.Rt[line], n))
        r = np.einsum("ni,ni->n", n, v) - h
        # Near a corner's diagonal the face is the noise's to choose; far off, another part's.
        keep = np.abs(np.abs(a) - np.abs(b)) > CORNER_SIGMAS * np.sqrt(2 * var)
        if step == PRISM_STEPS:
            keep &= r**2 < GATE_SIGMAS**2 * var
        kept = np.flatnonzero(keep)
        if len(kept) < 10:
            return None
        ne = n[kept] @ np.stack([f1, f2]).T
        along = v[kept] @ d
        roll = np.einsum("ni,ni->n", np.cross(d, n[kept]), v[kept])
        # The nuisances: the line's offsets and tilts along f1 and f2, the roll, the half-width.
        J_nuisance = np.column_stack([-ne, -along[:, None] * ne, roll, -np.ones(len(kept))])
        if step == PRISM_STEPS:
            return Prism(kept, r[kept], n[kept], var[kept], J_nuisance, h)
        w = 1.0 / var[kept]
        delta = -np.linalg.lstsq(J_nuisance * np.sqrt(w)[:, None], r[kept] * np.sqrt(w), rcond=None)[0]
        c = c + delta[0] * f1 + delta[1] * f2
        d = d + delta[2] * f1 + delta[3] * f2
        d /= np.linalg.norm(d)
        f1 = f1 + delta[4] * np.cross(d, f1)
        f1 -= (f1 @ d) * d
        f1 /= np.linalg.norm(f1)
        h += float(delta[5])
    return None


def prism_rows(
    beams: Beams, data: DenseData, mapping: LineMapping, noise: SensorNoise
) -> tuple[Linearized, list[PrismFit]]:
    """The members' prism rows at ``mapping`` (see the module): residuals (m), their derivatives
    w.r.t. the free parameters with the nuisances projected off, and the sensor's variances."""
    xyz, line = data.xyz_m[beams.point], data.line[beams.point]
    y = mapping.apply(xyz, line)
    rows: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    fits = []
    for k in range(beams.members):
        s = np.arange(beams.bounds[k], beams.bounds[k + 1])
        prism = fit_prism(y[s], xyz[s], line[s], mapping, noise)
        if prism is None:
            fits.append(PrismFit(len(s), 0, 0.0, 0.0))
            continue
        r, var, Jn = prism.r, prism.var, prism.J_nuisance
        fits.append(PrismFit(len(s), len(r), prism.half_width_m, float(np.sqrt(np.mean(r**2 / var)))))
        J = mapping.normal_derivative(prism.normal, xyz[s][prism.kept], line[s][prism.kept])
        r_x, J_x = without_nuisances(Jn, 1.0 / var, r, J)
        rows.append((r_x, J_x, var))
    if not rows:
        return Linearized(np.zeros(0), np.zeros((0, len(mapping.free))), np.zeros(0)), fits
    r_all, J_all, var_all = (np.concatenate(part) for part in zip(*rows, strict=True))
    return Linearized(r_all, J_all, var_all), fits


def design_rows(
    data: DenseData, mapping: LineMapping, noise: SensorNoise, terms: Terms, beams: Beams
) -> tuple[dict[str, Linearized], list[PrismFit]]:
    """Each design's linearised rows (see the module), and the prisms' fits."""
    lines_sensor = replace(
        beams,
        var_m2=(noise.angle_sigma_rad * data.range_m[beams.point]) ** 2,
        depth_var_m2=np.full(len(beams.point), noise.range_sigma_m**2),
        depth_shrink=np.zeros(len(beams.point)),
    )
    out = {
        "no members": terms.linearize(data, noise, mapping),
        "line members": replace(terms, beams=beams).linearize(data, noise, mapping),
        "lines, sensor variances": replace(terms, beams=lines_sensor).linearize(data, noise, mapping),
    }
    prism, fits = prism_rows(beams, data, mapping, noise)
    base = out["no members"]
    out["prism members"] = Linearized(
        np.concatenate([base.r, prism.r]), np.vstack([base.J, prism.J]), np.concatenate([base.var, prism.var])
    )
    return out, fits


@dataclass(frozen=True)
class CaseResult:
    """Per design its readings over the draws (``draw_bias.bias_table``), and the prisms' fits of
    the first draw."""

    readings: dict[str, dict[str, np.ndarray]]
    prisms: list[PrismFit]

    def to_json(self) -> dict[str, object]:
        return {
            "designs": {k: {q: v.tolist() for q, v in r.items()} for k, r in self.readings.items()},
            "prisms": [asdict(f) for f in self.prisms],
        }


def case(spec: ShapeCase, draws: int) -> CaseResult:
    """Each design's bias readings over the draws, and the prisms' fits (first draw)."""
    motion = random_motion(np.random.default_rng(spec.seed), distance_m=spec.distance_m)
    scene = Scene(scanner=Scanner(), shape=shape_named(spec.name))
    noise, loss = scene.scanner.noise, cauchy(CAUCHY_C)
    steps: dict[str, list[np.ndarray]] = {k: [] for k in DESIGNS}
    fits: list[PrismFit] = []
    for d in range(draws):
        sim, data, mapping, surf = at_truth(motion, scene, spec.seed + 1000 * d)
        matches, _ = last_stage_matches(data, mapping, surf, noise)
        beams = find_beams(data, mapping, surf, noise)
        terms = Terms(surf, matches, Beams.none())
        terms = terms.with_groups(find_grazing(data, mapping, surf, noise, exclude=beams.point), data, noise, mapping)
        designs, found = design_rows(data, mapping, noise, terms, beams)
        fits = fits or found
        for label, lin in designs.items():
            steps[label].append(newton_step(*normalised(lin), loss))
    bound_sd = np.sqrt(np.diag(bound_covariances(motion, scene, sim, float(sim.t_s.min())).facets))
    return CaseResult({label: bias_table(np.array(st), bound_sd) for label, st in steps.items()}, fits)


def rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


def main() -> None:
    args = draws_arguments(
        __doc__, ShapeCase("dish-boom", 100, 5), ShapeCase("dish-boom", 50, 2), draws=4, stem="member_prism"
    )
    print(machine())
    results = {}
    for spec in args.cases:
        out = case(spec, args.draws)
        results[str(spec)] = out.to_json()
        print(f"\n{spec}, {args.draws} draws; rotation parameters only")
        prisms = [[f.hits, f.kept, f"{100 * f.half_width_m:.1f}", f"{f.rms_sigmas:.2f}"] for f in out.prisms]
        print(table(prisms, ["member hits", "kept by the prism", "half-width cm", "residual RMS / sigma"]))
        rows = []
        for label, readings in out.readings.items():
            sd, bias = readings["sd_over_bound"][:6], readings["bias_over_bound"][:6]
            rows.append([label, f"{rms(sd):.2f}", *np.round(sd, 2), f"{rms(bias):.2f}"])
        print(table(rows, ["design", "spread RMS", *PARAM_NAMES[:6], "bias RMS"]))
    path = out_dir() / f"{args.stem}.json"
    path.write_text(json.dumps(results, indent=1))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
