"""Dense continuous-time refinement of the motion from line-scan frames (beyond the paper).

The frames are cut into surfels (:mod:`tumblescan.surfels`), each with a centroid ``a`` and a
normal at the reference time that move with the motion ``x``. For a source surfel ``a_s`` of
one frame and the nearest planar surfel ``a_t`` of another, the residual is the
centroid-to-plane distance

    r = n(x) . (a_s(x) - a_t(x)),    n = mean of the two normals (symmetric objective),
    var r = s^2 (v_s / N_s + v_t / N_t + d^2 (v_ns + v_nt) / 4)

with ``v`` the sensor's variance along ``n`` (range noise along the line of sight, angle noise
across it, ``SensorNoise``), ``N`` the surfels' point counts, ``d`` the in-plane offset
between the centroids, ``v_n`` the normals' tilt variances, and ``s`` a common scale estimated
from the residuals. A centroid carries what its points say along the normal, so every point
of a planar surfel enters the fit at the cost of one residual per partner frame. The fit
minimizes the Cauchy loss of ``r / sqrt(var r)`` over the 9 motion parameters by
Levenberg-Marquardt steps (kept only when they lower that cost: :mod:`.damping`) taken in the
spin and precession vectors (:mod:`.step_coords`), with correspondences re-found once points
have moved and the surfels rebuilt after large steps.

Correspondences and the residual model: :mod:`.matching`. Thin members (booms, truss wires)
that make no planar surfel join from the second stage on, each hit's offset across its
member's line (:mod:`.beams`); in the last stage, the hits seen at grazing incidence that no
planar surfel holds, against the other frames' planar surfels (:mod:`.grazing`). Their rows
follow the surfels' in the cost and the covariance (:mod:`.terms`): the members' variances from
their own spread, the grazing groups' scaled to the surfel pairs' robust scale.

Three stages: every surfel matched in a neighbouring frame (right correspondences even from
the initializer's rough start), then in random frames (the long time baselines fix the
rates), then in every other frame from the converged start (each brings its own noise).

Covariance: a sandwich with the Cauchy cost's Hessian, clustered by patch of the target at
``T`` (cubes of extent / 10: residuals of one patch, from every frame, share pooled normals
and the surface model's misfit), by the cluster jackknife (see :mod:`.covariance`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..._typing import FloatArray, IntArray
from ...geometry.rotations import axis_from_angles
from ...target.motion import N_PARAMS, canonical_params
from ..options import DenseConfig
from ..sensor import SensorNoise
from ..validation import canonical_cov
from .beams import Beams, find_beams
from .covariance import patches, sandwich
from .damping import LM_START, damped_step
from .data import DenseData
from .mapping import LineMapping
from .matching import (
    CAUCHY_C,
    Linearized,
    cauchy_cost,
    match,
    partners,
    robust_sigma,
    weights,
)
from .step_coords import StepCoords
from .surfels import Surfels, build_surfels
from .terms import Terms

ALL_FREE = tuple(range(N_PARAMS))
SPIN_ONLY_FREE = (0, 1, 2, 6, 7, 8)
# Rebuild the surfels, and re-find correspondences, once points have moved this share of a surfel.
SURFEL_REFRESH = 0.25
REMATCH = 0.05
PROBE_POINTS = 2000
# A stage that may be given up (refine_dense's give_up_scale) is, once this many of its steps
# leave the residuals over that scale: by then a sound start's first stage stood at 1.25 at most
# and its second at 1.04 (the real shapes' 120 jobs of seeds 0-9), wrong starts' first stages at
# 22.7 or more, which ran their 15 steps at 22-160 before (bench.linescan.stage_scales).
GIVE_UP_STEPS = 8
# Covariance clusters: patches of the target this share of its extent wide (see .covariance).
CLUSTER_FRACTION = 1 / 10


@dataclass(frozen=True)
class DenseFit:
    """Result of :func:`refine_dense`: canonical 9-vector, its 9x9 covariance, fit statistics.

    rms_m: RMS centroid-to-plane residual of the inliers; frame_rms_m: the same per frame (as
    source or target); residuals: centroid-to-plane residuals used; surfels: distinct source
    surfels; points: the points in them, on the members and in the grazing groups; scale: the
    common scale ``s`` of the centroid-to-plane residuals' model sigmas (about 1 when the motion
    fits; a wrong motion leaves residuals many times their model sigma).
    """

    x: FloatArray
    cov: FloatArray
    free: tuple[int, ...]
    rms_m: float
    frame_rms_m: FloatArray
    residuals: int
    surfels: int
    points: int
    iterations: int
    scale: float
    members: int = 0  # thin members fitted as lines (:mod:`.beams`)
    given_up: int = 0  # the stage in which it stopped (``give_up_scale``); 0: every stage ran
    given_up_scale: float = float("nan")  # that stage's scale, over every row it weighed

    @property
    def spin_only(self) -> bool:
        return self.free == SPIN_ONLY_FREE


@dataclass
class _Problem:
    data: DenseData
    free: tuple[int, ...]
    base: FloatArray
    config: DenseConfig
    noise: SensorNoise
    gauge_point: FloatArray | None

    def full(self, z: FloatArray) -> FloatArray:
        x = self.base.copy()
        x[list(self.free)] = z
        return x


def refine_dense(
    data: DenseData,
    x0: FloatArray,
    *,
    spin_only: bool = False,
    config: DenseConfig | None = None,
    noise: SensorNoise | None = None,
    seed: int = 0,
    converged: bool = False,
    gauge_point: FloatArray | None = None,
    on_iteration: Callable[[int, int], None] | None = None,
    give_up_scale: float | None = None,
) -> DenseFit:
    """Refine ``x0`` (a 9-vector at the reference time of ``data.tau_s``); see the module docstring.

    data: the frames (:func:`prepare`). spin_only: fix the precession rate at 0 and keep the
    centre on the spin axis, at the point nearest the points' centroid. noise: the sensor's noise model
    (weights, planarity test, correspondence gate). converged: ``x0`` is already a solution
    (of a superset of these frames, say): run the last stage only, from the tightest gate.
    gauge_point: spin-only, the point whose nearest axis point is reported as the centre
    (default: the points' centroid at ``T``); give the same one to compare two fits.
    on_iteration(step, max_steps): called after each step; it may raise to stop.
    give_up_scale: stop after any stage but the last that leaves the residuals more than this many
    times their model sigma (a start in another basin, which the later stages do not leave: a
    caller with another start to try), or within it once ``GIVE_UP_STEPS`` of its steps do; the
    fit is then that stage's.
    """
    cfg = config or DenseConfig()
    sensor = noise or SensorNoise()
    free = SPIN_ONLY_FREE if spin_only else ALL_FREE
    # In the chart the steps are taken in (rates >= 0, the polar angles in [0, pi]): step_coords.
    base = canonical_params(np.asarray(x0, dtype=float))
    rng = np.random.default_rng(seed)
    gauge = None
    if spin_only:
        base[3:6] = 0.0
        probe = _probe(data)
        gauge = (
            np.asarray(gauge_point, dtype=float)
            if gauge_point is not None
            else LineMapping(base, data.tau_s, free).apply(data.xyz_m[probe], data.line[probe]).mean(axis=0)
        )
    problem = _Problem(data, free, base, cfg, sensor, gauge)
    problem.base = _on_gauge(problem, base)
    z = problem.base[list(free)]
    step = 0
    cells = np.arange(len(data.cell_frame), dtype=np.int64)
    stages = [
        # 1. Neighbouring frames only: right correspondences even from a rough start.
        (partners(data, cells, rng, window=cfg.near_window, k=1), cfg.max_iterations),
        # 2. Any frame: long baselines pin the rates down.
        (partners(data, cells, rng, window=None, k=cfg.partners), cfg.max_iterations),
        # 3. More partners from the converged start: each brings its own target noise.
        (partners(data, cells, rng, window=None, k=cfg.fine_partners), cfg.fine_iterations),
    ]
    gate = max(data.extent_m / 20, 5 * sensor.range_sigma_m, 1.5 * data.surfel_m)
    # Thin members join from the second stage on: at T their strips line up only once the
    # frames roughly agree.
    with_beams = [False, cfg.beams, cfg.beams]
    # The grazing hits join in the last stage: they are gated at 3 of their own sigmas, which
    # only a converged motion keeps.
    with_grazing = [False, False, cfg.grazing]
    if converged:
        stages, gate = stages[2:], max(5 * sensor.range_sigma_m, 1.5 * data.surfel_m)
        with_beams, with_grazing = with_beams[2:], with_grazing[2:]
    total = sum(iterations for _, iterations in stages)
    terms: Terms | None = None
    for k, (((src, partner), iterations), beams_on, grazing_on) in enumerate(
        zip(stages, with_beams, with_grazing, strict=True)
    ):
        # Every stage but the last may be given up: its fit is the refinement's.
        may_give_up = give_up_scale if k < len(stages) - 1 else None
        z, terms, gate, step, scale = _iterate(
            problem,
            z,
            src,
            partner,
            terms,
            gate,
            iterations,
            beams_on,
            grazing_on,
            step=step,
            total=total,
            on_iteration=on_iteration,
            give_up_scale=may_give_up,
        )
        if may_give_up is not None and scale > may_give_up:
            # Seen: 17.6 after the first stage, 22.8 after two more (9 s on the long array at 100 m
            # seed 1), where a sound start's stood at 1.0. A start that matched next to nothing in
            # the first stage passes it (scale 0) and shows after the second (32.1, then 10.0).
            assert terms is not None
            return replace(_finish(problem, z, terms, step), given_up=k + 1, given_up_scale=scale)
    assert terms is not None
    return _finish(problem, z, terms, step)


def _iterate(
    problem: _Problem,
    z: FloatArray,
    src: IntArray,
    partner: IntArray,
    terms: Terms | None,
    gate: float,
    iterations: int,
    beams_on: bool,
    grazing_on: bool,
    *,
    step: int,
    total: int,
    on_iteration: Callable[[int, int], None] | None,
    give_up_scale: float | None = None,
) -> tuple[FloatArray, Terms, float, int, float]:
    """Levenberg-Marquardt steps on one set of (source, partner) pairs; ``gate`` is the largest
    distance to a matched surfel's centroid, tightened as the frames come together. Returns the
    parameters, the terms, the gate, the steps so far and the residuals' last common scale.
    give_up_scale: stop once ``GIVE_UP_STEPS`` steps leave that scale over this (the caller
    gives the start up)."""
    cfg, data, noise = problem.config, problem.data, problem.noise
    floor = max(5 * noise.range_sigma_m, 1.5 * data.surfel_m)
    probe = _probe(data)
    mapping = LineMapping(problem.full(z), data.tau_s, problem.free)

    def found_beams(surf: Surfels, mapping: LineMapping) -> Beams:
        return find_beams(data, mapping, surf, noise) if beams_on else Beams.none()

    if terms is None or _shift(data, probe, terms.surf.mapping, mapping) > SURFEL_REFRESH * data.surfel_m:
        surf = build_surfels(data, mapping, noise)
    else:
        surf = terms.surf
    # A stage's start is a new motion: the members (their hits and variances) are found anew.
    beams = found_beams(surf, mapping)
    terms = Terms(surf, match(data, mapping, surf, src, partner, gate), beams)
    if grazing_on:
        terms = terms.with_grazing(data, noise, mapping)
    matched_at, matched_gate = mapping, gate
    lam = LM_START
    vectors = StepCoords(problem.free)
    scale = float("nan")
    for taken_here in range(iterations):
        lin = terms.linearize(data, noise, mapping)
        w, scale = weights(lin)
        if give_up_scale is not None and taken_here >= GIVE_UP_STEPS and scale > give_up_scale:
            break
        sw = np.sqrt(w)
        rows = lin.J * sw[:, None]
        # Steps in the rotation vectors (a straight line along the valley of a nearly degenerate
        # motion, a curve in the angles: step_coords), unless an axis is undefined.
        coords = vectors if vectors.usable(z) else None
        if coords is not None:
            rows = rows @ coords.dz_dy(z)
        H, g = rows.T @ rows, -rows.T @ (lin.r * sw)
        taken = _damped_step(problem, z, H, g, lam, lin, scale, terms, coords)
        if taken is None:
            break
        dz, lam, mapping = taken
        # A Gauss-Newton step far below the parameters' own uncertainty changes nothing that
        # matters. Not the step taken: along a nearly degenerate direction (spin and precession
        # about nearly one axis) the damping leaves small steps far from the optimum.
        full = np.linalg.lstsq(H, g, rcond=None)[0]
        sd = scale * np.sqrt(np.diag(np.linalg.pinv(H, rcond=1e-12)))
        moved = float(np.max(np.abs(full) / np.maximum(sd, 1e-300)))
        z = z + dz
        step += 1
        if on_iteration is not None:
            on_iteration(step, total)
        if moved < cfg.tolerance:
            break
        # Tighten the gate as the frames come together. Surfels move rigidly with their lines,
        # so they are rebuilt only after large steps; correspondences once points have moved.
        gate = max(floor, min(gate, 4 * CAUCHY_C * robust_sigma(lin.r[: len(terms.matches.src)])))
        surf, beams = terms.surf, terms.beams
        if _shift(data, probe, surf.mapping, mapping) > SURFEL_REFRESH * data.surfel_m:
            surf = build_surfels(data, mapping, noise)
            beams = found_beams(surf, mapping)
        if (
            surf.mapping is mapping
            or gate < 0.9 * matched_gate
            or _shift(data, probe, matched_at, mapping) > REMATCH * data.surfel_m
        ):
            rematched = Terms(surf, match(data, mapping, surf, src, partner, gate), beams)
            if not grazing_on:
                terms = rematched
            elif surf is terms.surf:
                # The groups' targets (and the members they keep off) are still these: only the
                # pairs are found anew. Finding the groups costs a query per grazing hit and
                # frame; within the last stage the points move by less than a quarter surfel.
                terms = replace(rematched, grazing=terms.grazing, grazing_scale2=terms.grazing_scale2)
            else:
                terms = rematched.with_grazing(data, noise, mapping)
            matched_at, matched_gate = mapping, gate

    return z, terms, gate, step, scale


def _damped_step(
    problem: _Problem,
    z: FloatArray,
    H: FloatArray,
    g: FloatArray,
    lam: float,
    lin: Linearized,
    scale: float,
    terms: Terms,
    coords: StepCoords | None,
) -> tuple[FloatArray, float, LineMapping] | None:
    """The Levenberg-Marquardt step (:func:`.damping.damped_step`) that lowers the Cauchy cost on
    these correspondences, members and grazing groups, as ``(dz, next damping, mapping)``; None
    when none does. ``H`` and ``g`` are in the step coordinates ``coords`` (in ``z`` itself when
    None); the step returned is in ``z``."""
    data = problem.data

    def trial(y: FloatArray) -> tuple[float, tuple[FloatArray, LineMapping]]:
        moved = z + y if coords is None else coords.z_of(coords.y_of(z) + y)
        x = _on_gauge(problem, problem.full(moved))
        mapping = LineMapping(x, data.tau_s, problem.free)
        r = terms.residuals(data, problem.noise, mapping)
        return cauchy_cost(r / np.sqrt(lin.var), scale), (x, mapping)

    taken = damped_step(H, g, lam, cauchy_cost(lin.r / np.sqrt(lin.var), scale), trial)
    if taken is None:
        return None
    lam, (x, mapping) = taken
    return np.asarray(x[list(problem.free)] - z, dtype=float), lam, mapping


def _probe(data: DenseData) -> IntArray:
    """About ``PROBE_POINTS`` points spread evenly over the cloud."""
    return np.arange(0, len(data.xyz_m), max(1, len(data.xyz_m) // PROBE_POINTS), dtype=np.int64)


def _shift(data: DenseData, probe: IntArray, before: LineMapping, after: LineMapping) -> float:
    """Largest displacement of the probe points at ``T`` between two motions (m)."""
    xyz, line = data.xyz_m[probe], data.line[probe]
    return float(np.max(np.linalg.norm(after.apply(xyz, line) - before.apply(xyz, line), axis=1), initial=0.0))


def _gauge_row(problem: _Problem, x: FloatArray) -> FloatArray | None:
    """Spin-only: ``d/dz [l_s . (O - gauge_point)]`` (the centre's slide along the spin axis), else None."""
    if problem.gauge_point is None:
        return None
    row = np.zeros(len(problem.free))
    row[list(problem.free).index(6) :] = axis_from_angles(x[0], x[1])
    return row


def _on_gauge(problem: _Problem, x: FloatArray) -> FloatArray:
    """Spin-only: the centre slid along the spin axis to the point nearest the gauge point.
    Any point of the axis gives the same motion, so the cost does not change."""
    if problem.gauge_point is None:
        return x
    l_s = axis_from_angles(x[0], x[1])
    out = x.copy()
    out[6:9] -= l_s * float(l_s @ (x[6:9] - problem.gauge_point))
    return out


def _finish(problem: _Problem, z: FloatArray, terms: Terms, steps: int) -> DenseFit:
    """Covariance and residual statistics at ``z`` with the last step's correspondences."""
    data = problem.data
    x = problem.full(z)
    mapping = LineMapping(x, data.tau_s, problem.free)
    lin = terms.linearize(data, problem.noise, mapping)
    cluster = patches(terms.positions(data, mapping), CLUSTER_FRACTION * data.extent_m)
    # The covariance with the scale the fit weighed every row by; the fit's statistics from the
    # centroid-to-plane residuals alone (the members' offsets are scaled by their own spread).
    cov_free = sandwich(lin.J, lin.r, lin.var, CAUCHY_C * weights(lin)[1], cluster, _gauge_row(problem, x))
    m, surf = terms.matches, terms.surf
    n = len(m.src)
    scale = weights(Linearized(lin.r[:n], lin.J[:n], lin.var[:n]))[1]
    cov9 = np.zeros((N_PARAMS, N_PARAMS))
    idx = np.array(problem.free)
    cov9[np.ix_(idx, idx)] = cov_free
    inlier = np.abs(lin.r[:n]) <= 3 * scale * np.sqrt(lin.var[:n])
    sources = np.unique(m.src)
    r_in = lin.r[:n][inlier]
    frame_sq = np.zeros(data.n_frames)
    frame_n = np.zeros(data.n_frames)
    for fr in (data.cell_frame[m.src], data.cell_frame[m.dst]):
        np.add.at(frame_sq, fr[inlier], r_in**2)
        np.add.at(frame_n, fr[inlier], 1)
    frame_rms = np.sqrt(frame_sq / np.maximum(frame_n, 1))
    frame_rms[frame_n == 0] = np.nan
    return DenseFit(
        x=canonical_params(x),
        cov=canonical_cov(x, cov9),
        free=problem.free,
        rms_m=float(np.sqrt(np.mean(r_in**2))) if len(r_in) else float("nan"),
        frame_rms_m=frame_rms,
        residuals=n,
        surfels=len(sources),
        points=int(surf.count[sources].sum()) + len(terms.beams.point) + terms.grazing.hits,
        iterations=steps,
        scale=scale,
        members=terms.beams.members,
    )
