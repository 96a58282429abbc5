"""How much a point-to-line term could recover: the hits the dense fit leaves out, by class.

    python -m bench.linescan.line_potential [--shapes telescope dish-boom octagon-truss box]
                                            [--seeds 0 1 2] [--distances 50] [--ratio 8]

At the true motion (the bench's seeded motion and frames, ``T`` the first hit's time), surfels
built as the estimator builds them (:func:`~tumblescan.linescan.dense.surfels.build_surfels`).
Every hit outside a planar surfel is put in one class, in this order:

- ``linear``: its cell, or its cell with the neighbours of its frame's view at a similar range
  that are not planar (a 3x3 block, for booms as wide as a cell), is a line: the points' scatter
  at ``T``, less the range noise along the line of sight (``s_r^2 u u^T``), has eigenvalues
  ``l0 <= l1 <= l2`` with ``l1 <= l2 / ratio`` (one dominant direction), at least 5 points;
- ``edge band``: an interior cell (every side neighbour hit at a similar range), not linear;
- ``silhouette``: a cell on the border of the view, of the target or of an occlusion;
- ``spurious``: a return left out before the cells (:mod:`~tumblescan.linescan.dense.returns`).

Beside it the truth: the hits on a *beam* (a connected part of the mesh whose two smaller
extents are at most ``BEAM_MAX_WIDTH_M`` and the largest ``BEAM_MIN_ASPECT`` times more).

Bounds (``dense_bound.py``, every one over the bound of all hits; gap closed = ``(used - x) /
(used - all)``):

- face model: the hits given, each face of the mesh a nuisance plane (the most any estimator
  modelling the target as planes gets from them);
- line model: the used hits' face bound plus the beam hits of the set as lines. Each beam is
  one line at ``T`` (4 nuisance parameters: 2 offsets, 2 tilts), and each hit gives the offset
  ``r = e . (M(x) - c_k)`` across the line and across the line of sight (``lateral``,
  ``e = d x u / |d x u|``, variance ``(s_a rho)^2`` plus the beam's projected cross-section, the
  variance of the true hits' lateral offsets in that frame): the silhouette of a centrally
  symmetric section is centred on the axis, so this offset has no bias from the view. ``2-D``
  adds the offset along the line of sight (variance ``s_r^2`` plus the section's depth spread),
  whose mean moves with the view (the visible faces lie on the sensor's side of the axis): an
  optimistic figure, as if that bias were modelled.
"""

from __future__ import annotations

import argparse

import numpy as np
from numpy.typing import NDArray

from tumblescan import Motion, Scanner, Scene, random_motion, simulate_frames
from tumblescan.linescan.dense.data import MAX_RANGE_STEP, DenseData
from tumblescan.linescan.dense.faces import SIDE_NEIGHBOURS, flat_cells
from tumblescan.linescan.dense.mapping import LineMapping
from tumblescan.linescan.dense.members import _line_shape, _moments
from tumblescan.linescan.dense.surfels import _cell_moments, _noise_free_normals, build_surfels, normal_variance
from tumblescan.linescan.sensor import SensorNoise, perpendiculars
from tumblescan.linescan.simulate import FrameCloud
from tumblescan.target.motion import apply_rotation

from ..common import table
from .dense_bound import _body_frame, dense_bound, face_of_hits
from .real_shapes import shape_named
from .truth import dense_data

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]
PARAMS = ("spin_axis_deg", "spin_rate_deg_s", "precession_axis_deg", "precession_rate_deg_s")
# A beam: a connected part of the mesh this thin across (m) and this many times longer.
BEAM_MAX_WIDTH_M = 0.2
BEAM_MIN_ASPECT = 5.0
MIN_LINE_POINTS = 5
# Incidence beyond this (|cos| between line of sight and normal) counts as grazing.
GRAZING_COS = 0.3


def beam_of_hits(scene: Scene, motion: Motion, reference_m: FloatArray) -> IntArray:
    """Each hit's beam (a connected part of the mesh that is long and thin), ``-1`` when on none."""
    from tumblescan._open3d import load_open3d

    o3d = load_open3d()
    mesh = scene.shape.mesh()
    part = np.asarray(mesh.cluster_connected_triangles()[0], dtype=np.int64)
    vertices = np.asarray(mesh.vertices, dtype=float)
    triangles = np.asarray(mesh.triangles, dtype=np.int64)
    is_beam = np.zeros(int(part.max()) + 1, dtype=np.bool_)
    for k in range(len(is_beam)):
        pts = vertices[np.unique(triangles[part == k])]
        centred = pts - pts.mean(axis=0)
        axes = np.linalg.svd(centred, full_matrices=False)[2]
        ext = np.sort(np.ptp(centred @ axes.T, axis=0))
        is_beam[k] = ext[1] <= BEAM_MAX_WIDTH_M and ext[2] >= BEAM_MIN_ASPECT * max(ext[1], 1e-9)
    body, _ = _body_frame(scene, motion, reference_m)
    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(o3d.core.Tensor(vertices.astype(np.float32)), o3d.core.Tensor(triangles.astype(np.uint32)))
    tri = rc.compute_closest_points(o3d.core.Tensor(body.astype(np.float32)), nthreads=0)["primitive_ids"].numpy()
    tri = tri.astype(np.int64)
    valid = tri < len(triangles)
    hit_part = np.where(valid, part[np.where(valid, tri, 0)], -1)
    return np.where((hit_part >= 0) & is_beam[np.maximum(hit_part, 0)], hit_part, -1).astype(np.int64)


def _is_line(count: FloatArray, s1: FloatArray, s2: FloatArray, los_t: FloatArray, range_var_m2: float,
             ratio: float) -> BoolArray:  # fmt: skip
    """One dominant direction of the scatter less the range noise along ``los_t`` (unit, at ``T``)."""
    return _line_shape(count, s1, s2, los_t, range_var_m2, ratio=ratio, min_points=MIN_LINE_POINTS)[0]


def classify(data: DenseData, mapping: LineMapping, planar_point: BoolArray, planar_cell: BoolArray,
             range_sigma_m: float, ratio: float) -> tuple[BoolArray, BoolArray, BoolArray]:  # fmt: skip
    """Whether each (kept) point's cell is a line, alone and with its non-planar neighbours, and
    whether it is an isolated one: linear, with no planar neighbour at a similar range (a strip of a
    plate along an edge or the silhouette has its plate's cells beside it; a boom has none)."""
    m = len(data.cell_frame)
    y = mapping.apply(data.xyz_m, data.line) - mapping.center
    u = data.xyz_m / np.linalg.norm(data.xyz_m, axis=1, keepdims=True)
    count, s1, s2 = _moments(data.cell, y, m)
    u_t = mapping.rotate(u, data.line)
    los = np.stack([np.bincount(data.cell, u_t[:, i], minlength=m) for i in range(3)], 1).astype(float)
    los /= np.maximum(np.linalg.norm(los, axis=1, keepdims=True), 1e-300)
    rho = np.bincount(data.cell, np.linalg.norm(data.xyz_m, axis=1), minlength=m) / np.maximum(count, 1)
    line_cell = _is_line(count, s1, s2, los, range_sigma_m**2, ratio)
    # The 3x3 block: the cell and its neighbours at a similar range that are not planar.
    bc, b1, b2 = count.copy(), s1.copy(), s2.copy()
    beside_plane = np.zeros(m, dtype=bool)
    for k in range(data.neighbours.shape[1]):
        nb = data.neighbours[:, k]
        near = (nb >= 0) & (np.abs(rho[np.maximum(nb, 0)] - rho) <= MAX_RANGE_STEP * data.surfel_m)
        beside_plane |= near & planar_cell[np.maximum(nb, 0)]
        ok = near & ~planar_cell[np.maximum(nb, 0)]
        j = np.maximum(nb, 0)
        bc += np.where(ok, count[j], 0.0)
        b1 += np.where(ok[:, None], s1[j], 0.0)
        b2 += np.where(ok[:, None, None], s2[j], 0.0)
    line_block = _is_line(bc, b1, b2, los, range_sigma_m**2, ratio)
    isolated = (line_cell | line_block) & ~beside_plane
    return (
        line_cell[data.cell] & ~planar_point,
        line_block[data.cell] & ~planar_point,
        isolated[data.cell] & ~planar_point,
    )


REASONS = ("thick", "silhouette", "range step", "face test")


def flat_of_cells(data: DenseData, mapping: LineMapping, noise: SensorNoise) -> tuple[BoolArray, FloatArray]:
    """Whether each cell's own points at ``mapping`` pass
    :func:`~tumblescan.linescan.dense.faces.flat_cells` ``(m,)``, and its centroid at observation
    ``(m, 3)``."""
    m = len(data.cell_frame)
    y = mapping.apply(data.xyz_m, data.line) - mapping.center
    count, mean, cov, line = _cell_moments(data, y, data.cell, m)
    Rt = mapping.Rt[line]
    anchor_obs = mapping.center + np.einsum("nji,nj->ni", Rt, mean)
    w, normal_ref, _ = _noise_free_normals(cov, Rt, anchor_obs, noise)
    flat = flat_cells(w, normal_variance(noise, anchor_obs, np.einsum("nji,nj->ni", Rt, normal_ref)), count)
    return np.asarray(flat), np.asarray(anchor_obs)


def why_left_out(data: DenseData, mapping: LineMapping, noise: SensorNoise) -> IntArray:
    """The first test each (kept) point's own cell fails, an index into ``REASONS``: not flat
    (:func:`~tumblescan.linescan.dense.faces.flat_cells`), a side neighbour in the view not hit,
    a side neighbour at a range more than ``MAX_RANGE_STEP`` cells away, or flat and interior yet
    not planar (the face tests); ``-1`` for a cell that passes all of the first three."""
    flat, anchor_obs = flat_of_cells(data, mapping, noise)
    side = data.neighbours[:, list(SIDE_NEIGHBOURS)]
    rho = np.linalg.norm(anchor_obs, axis=1)
    missing = np.any(side < 0, axis=1)
    step = np.any(np.abs(rho[np.maximum(side, 0)] - rho[:, None]) > MAX_RANGE_STEP * data.surfel_m, axis=1)
    reason = np.select([~flat, missing, step], [0, 1, 2], default=3)
    return np.asarray(reason[data.cell], dtype=np.int64)


def line_rows(
    mapping: LineMapping, xyz_obs: FloatArray, line: IntArray, centre: FloatArray, direction: FloatArray,
    *, along_sight: bool = False,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:  # fmt: skip
    """Each point's offset from the line ``centre + s direction`` (at ``T``, unit ``direction``),
    across it and across the point's line of sight (``along_sight``: along the sight instead):

        r = e . (M(p) - c),    e = d x u / |d x u|    (u: the line of sight turned to ``T``)

    Returns ``r`` ``(n,)`` (m), ``dr/dx`` ``(n, k)`` for the mapping's free parameters (``e``
    held), ``dr/dl`` ``(n, 4)`` for the line's offsets ``c + E a`` and tilts ``d + E b`` (``E``:
    :func:`perpendiculars` of ``d``; ``r`` changes by ``-e.E (a + s b)``, ``s`` the point's
    coordinate along the line) and ``e`` ``(n, 3)``."""
    y = mapping.apply(xyz_obs, line)
    u_t = mapping.rotate(xyz_obs / np.linalg.norm(xyz_obs, axis=1, keepdims=True), line)
    e = u_t - np.outer(u_t @ direction, direction) if along_sight else np.cross(direction, u_t)
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    offset = np.einsum("ni,ni->n", e, y - centre)
    E = np.stack(perpendiculars(direction[None, :]), axis=1)[0]  # (2, 3)
    ee = e @ E.T
    s = (y - centre) @ direction
    J_l = -np.concatenate([ee, s[:, None] * ee], axis=1)
    return offset, mapping.normal_derivative(e, xyz_obs, line), J_l, e


def line_information(motion: Motion, scene: Scene, sim: FrameCloud, T: float, beam: IntArray, hits: BoolArray,
                     *, two_d: bool) -> FloatArray:  # fmt: skip
    """Fisher information ``(9, 9)`` on the motion at ``T`` from ``hits`` on beams modelled as lines,
    each beam's 4 line parameters eliminated (module docstring): :func:`line_rows` of the true
    hits, with the variance ``(s_a rho)^2`` (``s_r^2`` along the sight) plus the spread of the
    true hits' offsets in each frame (the section seen)."""
    x = motion.at_reference(T).params()
    keep = hits & (beam >= 0)
    key = sim.frame.astype(np.int64) * scene.scanner.lines + sim.line
    _, first, line = np.unique(key[keep], return_index=True, return_inverse=True)
    mapping = LineMapping(x, sim.t_s[keep][first] - T, tuple(range(9)))
    p = sim.xyz_true_m[keep]
    y = mapping.apply(p, line)
    rho = np.linalg.norm(p, axis=1)
    _, b = np.unique(beam[keep], return_inverse=True)
    nb = int(b.max()) + 1 if len(b) else 0
    info = np.zeros((9, 9))
    F_ml = np.zeros((nb, 9, 4))
    F_ll = np.zeros((nb, 4, 4))
    noise = scene.scanner.noise
    frame = sim.frame[keep].astype(np.int64)
    for k in range(nb):
        on = b == k
        c = y[on].mean(axis=0)
        d = np.linalg.svd(y[on] - c, full_matrices=False)[2][0]
        kinds = [(False, (noise.angle_sigma_rad * rho[on]) ** 2)]
        if two_d:
            kinds.append((True, np.full(int(on.sum()), noise.range_sigma_m**2)))
        fr = frame[on]
        for along_sight, sensor_var in kinds:
            off, J_m, J_l, _ = line_rows(mapping, p[on], line[on], c, d, along_sight=along_sight)
            # The section's spread across the line in each frame (the hits' true offsets).
            cnt = np.bincount(fr)
            mean = np.bincount(fr, off) / np.maximum(cnt, 1)
            spread = np.bincount(fr, off**2) / np.maximum(cnt, 1) - mean**2
            w = 1.0 / (sensor_var + spread[fr])
            info += (J_m * w[:, None]).T @ J_m
            F_ml[k] += (J_m * w[:, None]).T @ J_l
            F_ll[k] += (J_l * w[:, None]).T @ J_l
    absorbed = np.einsum("kij,kjl,kml->im", F_ml, np.linalg.pinv(F_ll, rcond=1e-10, hermitian=True), F_ml)
    return np.asarray(info - absorbed)


def _simulated(name: str, distance_m: float, seed: int, size: int) -> tuple[Motion, Scene, FrameCloud, float]:
    """One seeded motion of shape ``name`` and its frames: (motion, scene, simulation, the first
    hit's time T in s)."""
    motion = random_motion(np.random.default_rng(seed), distance_m=distance_m)
    scene = Scene(scanner=Scanner(lines=size, pixels=size), shape=shape_named(name))
    sim = simulate_frames(motion, scene, seed=seed)
    return motion, scene, sim, float(sim.t_s.min())


def case(name: str, distance_m: float, seed: int, size: int, ratio: float) -> list[list[object]]:
    """One motion's class shares and bounds (rows of the printed tables)."""
    motion, scene, sim, T = _simulated(name, distance_m, seed, size)
    noise = scene.scanner.noise
    data = dense_data(sim, T, noise.range_sigma_m)
    mapping = LineMapping(motion.at_reference(T).params(), data.tau_s, tuple(range(9)))
    surf = build_surfels(data, mapping, noise)
    n = len(sim.xyz_m)
    kept = np.ones(n, dtype=bool) if data.kept is None else data.kept
    planar_pt = surf.planar[surf.point_cell]
    lc, lb, li = classify(data, mapping, planar_pt, surf.planar, noise.range_sigma_m, ratio)
    interior = data.interior[data.cell]

    def full(v: BoolArray) -> BoolArray:
        out = np.zeros(n, dtype=bool)
        out[kept] = v
        return out

    used = full(planar_pt)
    linear = full(lc | lb)
    isolated = full(li)
    edge = full(~planar_pt & ~(lc | lb) & interior)
    silhouette = full(~planar_pt & ~(lc | lb) & ~interior)
    beam = beam_of_hits(scene, motion, sim.reference_m)
    on_beam = beam >= 0
    faces = face_of_hits(scene, motion, sim.reference_m)

    def pct(v: BoolArray) -> str:
        return f"{100 * v.mean():.1f}"

    # Incidence: |cos| between each hit's line of sight and its face's normal at observation.
    face, normals = faces
    tau_obs = sim.t_s - motion.reference_time_s
    n_obs = np.asarray(apply_rotation(motion.params(), tau_obs, normals[np.maximum(face, 0)]), dtype=float)
    cos = np.abs(np.einsum("ni,ni->n", n_obs, sim.xyz_true_m)) / np.linalg.norm(sim.xyz_true_m, axis=1)
    cos[face < 0] = np.nan

    def grazing(v: BoolArray) -> str:
        return f"{np.nanmedian(cos[v]):.2f} / {100 * np.mean(cos[v & (face >= 0)] < GRAZING_COS):.0f}"

    on_b = linear & on_beam
    reason = np.full(n, -1, dtype=np.int64)
    reason[kept] = why_left_out(data, mapping, noise)
    graze_out = ~used & (cos < GRAZING_COS)
    why = " / ".join(f"{100 * np.mean(reason[graze_out] == k):.0f}" for k in range(len(REASONS)))
    # Another face's points in the left-out grazing hits' cells: the bias an estimator taking them risks.
    cell_of = np.full(n, -1, dtype=np.int64)
    cell_of[kept] = data.cell
    sel = graze_out & (face >= 0) & (cell_of >= 0)
    pairs, cnt = np.unique(np.stack([cell_of[sel], face[sel]]), axis=1, return_counts=True)
    majority = np.zeros(int(cell_of.max()) + 1)
    np.maximum.at(majority, pairs[0], cnt)
    mixed = 1.0 - majority[np.unique(pairs[0])].sum() / max(sel.sum(), 1)
    shares = [
        name, seed, pct(used), pct(linear), pct(full(lc)), pct(edge), pct(silhouette), pct(~kept), pct(on_beam),
        pct(on_beam & ~used), pct(on_b), f"{100 * on_b.sum() / max(linear.sum(), 1):.0f}", pct(isolated),
        pct(isolated & on_beam), f"{100 * (isolated & on_beam).sum() / max(isolated.sum(), 1):.0f}", grazing(used),
        grazing(linear & ~on_beam), grazing(~used), pct(~used & (cos < GRAZING_COS)),
        pct(~used & (cos < GRAZING_COS) & full(interior)), why, f"{100 * mixed:.1f}",
    ]  # fmt: skip
    b_all = dense_bound(motion, scene, sim, T, faces=faces)
    b_used = dense_bound(motion, scene, sim, T, hits=used, faces=faces)
    face_sets = [
        ("linear", linear), ("linear (cell)", full(lc)), ("linear off beams", linear & ~on_beam),
        ("isolated", isolated), ("grazing", cos < GRAZING_COS), ("non-grazing", cos >= GRAZING_COS),
        ("edge band", edge), ("silhouette", silhouette), ("beam", on_beam),
    ]  # fmt: skip
    sets = [(f"face: used+{label}", dense_bound(motion, scene, sim, T, hits=used | v, faces=faces))
            for label, v in face_sets]  # fmt: skip
    line_sets = [("line lat: used+linear beam", linear, False), ("line lat: used+isolated beam", isolated, False),
                 ("line lat: used+beam", on_beam, False), ("line 2-D: used+beam", on_beam, True)]  # fmt: skip
    for label, hits, two_d in line_sets:
        extra = line_information(motion, scene, sim, T, beam, hits & ~used, two_d=two_d) if on_beam.any() else None
        sets.append((label, dense_bound(motion, scene, sim, T, hits=used, faces=faces, extra_information=extra)))
    bounds = []
    for label, b in [("used", b_used), *sets]:
        ratios = [b[p] / b_all[p] for p in PARAMS]
        closed = [(b_used[p] - b[p]) / max(b_used[p] - b_all[p], 1e-300) for p in PARAMS]
        bounds.append([name, seed, label, *[f"{r:.2f}" for r in ratios], f"{100 * np.median(closed):.0f}"])
    return [shares, *bounds]


def range_step_sweep(name: str, distance_m: float, seed: int, size: int, steps: list[float]) -> list[list[object]]:
    """The interior test's range step (``data.MAX_RANGE_STEP``, in cells) at other values: the
    share of hits in planar surfels at the true motion, their bound over the bound of all hits,
    and the share of them not on their surfel's main face (the bias the test is there to stop).
    (The branch ``wip-ls-line``'s commit 2abf78b adds ``4p``: the step and a test of the
    neighbours on the cell's plane; docs/linescan-rounds.md.)"""
    from tumblescan.linescan.dense import data as data_module

    motion, scene, sim, T = _simulated(name, distance_m, seed, size)
    noise = scene.scanner.noise
    faces = face_of_hits(scene, motion, sim.reference_m)
    b_all = dense_bound(motion, scene, sim, T, faces=faces)
    rows: list[list[object]] = []
    default = data_module.MAX_RANGE_STEP
    try:
        for step in steps:
            data_module.MAX_RANGE_STEP = step
            data = dense_data(sim, T, noise.range_sigma_m)
            mapping = LineMapping(motion.at_reference(T).params(), data.tau_s, tuple(range(9)))
            surf = build_surfels(data, mapping, noise)
            kept = np.ones(len(sim.xyz_m), dtype=bool) if data.kept is None else data.kept
            used = np.zeros(len(kept), dtype=bool)
            used[kept] = surf.planar[surf.point_cell]
            cell = np.full(len(kept), -1, dtype=np.int64)
            cell[kept] = surf.point_cell
            sel = used & (faces[0] >= 0)
            pairs, cnt = np.unique(np.stack([cell[sel], faces[0][sel]]), axis=1, return_counts=True)
            majority = np.zeros(int(cell.max()) + 1)
            np.maximum.at(majority, pairs[0], cnt)
            other = 1.0 - majority.sum() / max(sel.sum(), 1)
            b = dense_bound(motion, scene, sim, T, hits=used, faces=faces)
            rows.append([name, seed, f"{step:g}", f"{100 * used.mean():.1f}", f"{100 * other:.2f}",
                         *[f"{b[p] / b_all[p]:.2f}" for p in PARAMS]])  # fmt: skip
    finally:
        data_module.MAX_RANGE_STEP = default
    return rows


SWEEP_HEADER = ["shape", "seed", "range step (cells)", "used %", "on another face %", "spin axis", "spin rate",
                "prec axis", "prec rate"]  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--shapes", nargs="+", default=["telescope", "dish-boom", "octagon-truss", "box"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--distances", nargs="+", type=float, default=[50.0])
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--ratio", type=float, default=8.0, help="l2 / l1 above which a cell is a line")
    parser.add_argument("--range-steps", nargs="+", type=float, default=None,
                        help="instead: the interior test's range step at these values (cells)")  # fmt: skip
    args = parser.parse_args()
    if args.range_steps:
        rows = []
        for dist in args.distances:
            for name in args.shapes:
                for s in args.seeds:
                    rows += range_step_sweep(name, dist, s, args.size, args.range_steps)
                    print(table(rows[-len(args.range_steps) :], SWEEP_HEADER), flush=True)
        print(f"\nbound of the used hits over the bound of all hits, by range step\n{table(rows, SWEEP_HEADER)}")
        return
    for dist in args.distances:
        shares, bounds = [], []
        for name in args.shapes:
            for s in args.seeds:
                rows = case(name, dist, s, args.size, args.ratio)
                shares.append(rows[0])
                bounds += rows[1:]
                print(table([rows[0]], SHARE_HEADER), "\n", table(rows[1:], BOUND_HEADER), flush=True)
        print(f"\n{dist:g} m: shares of all hits, %")
        print(table(shares, SHARE_HEADER))
        print(f"\n{dist:g} m: bound over the bound of all hits (face model); gap closed: median over the 4")
        print(table(bounds, BOUND_HEADER), flush=True)


SHARE_HEADER = ["shape", "seed", "used", "linear", "linear (cell)", "edge band", "silhouette", "spurious",
                "on beams", "beams left out", "linear on beams", "linear: beam purity %", "isolated linear",
                "isolated on beams", "isolated: purity %", "used: cos median / % grazing",
                "linear off beams: cos / % grazing", "left out: cos / % grazing", "left out grazing",
                "of which interior", "left-out grazing: thick/silh./step/face %", "other face's %"]  # fmt: skip
BOUND_HEADER = ["shape", "seed", "hits", "spin axis", "spin rate", "prec axis", "prec rate", "gap closed %"]

if __name__ == "__main__":
    main()
