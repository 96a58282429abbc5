"""The bench's measure of what a point-to-line term could recover: beams, line offsets, their bound."""

from __future__ import annotations

from functools import cache

import numpy as np
from bench.linescan.dense_bound import dense_bound, face_of_hits, fitted_hits
from bench.linescan.line_potential import beam_of_hits, classify, line_information, line_rows
from bench.linescan.truth import dense_data

from tumblescan import Motion, Scanner, Scene, simulate_frames
from tumblescan.linescan.dense.mapping import LineMapping
from tumblescan.linescan.dense.surfels import build_surfels
from tumblescan.linescan.sensor import perpendiculars
from tumblescan.linescan.simulate import FrameCloud
from tumblescan.target.shape import SatelliteShape
from tumblescan.target.shapes import OctagonTrussShape

from ..conftest import motion_for

WIRE_M = OctagonTrussShape().wire_m


@cache
def _truss() -> tuple[Motion, Scene, FrameCloud, float]:
    motion = motion_for(0, distance_m=50.0)
    scene = Scene(scanner=Scanner(lines=160, pixels=160), shape=OctagonTrussShape())
    sim = simulate_frames(motion, scene, seed=0)
    return motion, scene, sim, float(sim.t_s.min())


def _largest_beam(beam: np.ndarray) -> np.ndarray:
    ids, counts = np.unique(beam[beam >= 0], return_counts=True)
    return np.asarray(beam == ids[np.argmax(counts)])


def _line_through(y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c = y.mean(axis=0)
    return c, np.linalg.svd(y - c, full_matrices=False)[2][0]


def test_the_truss_wires_are_beams_and_the_box_has_none() -> None:
    motion, scene, sim, T = _truss()
    beam = beam_of_hits(scene, motion, sim.reference_m)
    assert 0.02 < np.mean(beam >= 0) < 0.2  # the tower, not the bus and its panels
    # Every hit given a beam lies on that wire: within its diagonal of the line through its hits
    # (which lies inside the section: the hits' mean leans towards the faces seen).
    ref = motion.position(sim.reference_m, np.full(len(beam), T))
    for b in np.unique(beam[beam >= 0]):
        on = beam == b
        if on.sum() < 20:
            continue
        c, d = _line_through(ref[on])
        off = ref[on] - c - np.outer((ref[on] - c) @ d, d)
        assert np.linalg.norm(off, axis=1).max() <= WIRE_M * np.sqrt(2) + 2e-3
    box = Scene(scanner=Scanner(lines=64, pixels=64), shape=SatelliteShape())
    box_sim = simulate_frames(motion, box, seed=0)
    assert np.all(beam_of_hits(box, motion, box_sim.reference_m) == -1)


def _largest_beam_lines(
    motion: Motion, scene: Scene, sim: FrameCloud, T: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The largest beam's hits (mask), each hit's line of its frame (index), the lines' time
    offsets from ``T`` (s) and the true motion's parameters at ``T``."""
    on = _largest_beam(beam_of_hits(scene, motion, sim.reference_m))
    key = sim.frame[on].astype(np.int64) * scene.scanner.lines + sim.line[on]
    _, first, line = np.unique(key, return_index=True, return_inverse=True)
    return on, line, sim.t_s[on][first] - T, motion.at_reference(T).params()


def test_a_wire_is_a_line_at_the_true_motion_and_not_at_a_wrong_one() -> None:
    motion, scene, sim, T = _truss()
    on, line, tau, x = _largest_beam_lines(motion, scene, sim, T)
    truth = LineMapping(x, tau, tuple(range(9)))
    c, d = _line_through(truth.apply(sim.xyz_true_m[on], line))
    r_true = line_rows(truth, sim.xyz_true_m[on], line, c, d)[0]
    # Across the line and the sight, a hit lies at most the wire's diagonal off the line.
    assert np.abs(r_true).max() <= WIRE_M * np.sqrt(2) + 1e-3
    wrong_x = x.copy()
    wrong_x[2] += np.radians(2.0)  # spin rate off by 2 deg/s
    wrong = LineMapping(wrong_x, tau, tuple(range(9)))
    c_w, d_w = _line_through(wrong.apply(sim.xyz_true_m[on], line))
    r_wrong = line_rows(wrong, sim.xyz_true_m[on], line, c_w, d_w)[0]
    assert np.sqrt(np.mean(r_wrong**2)) > 3 * np.sqrt(np.mean(r_true**2))


def test_line_rows_derivatives_are_those_of_the_offsets() -> None:
    motion, scene, sim, T = _truss()
    on, line, tau, x = _largest_beam_lines(motion, scene, sim, T)
    p = sim.xyz_true_m[on]
    mapping = LineMapping(x, tau, tuple(range(9)))
    c, d = _line_through(mapping.apply(p, line))
    r, J_m, J_l, e = line_rows(mapping, p, line, c, d)
    h = 1e-6
    for i in range(9):
        xp = x.copy()
        xp[i] += h
        moved = np.einsum("ni,ni->n", e, LineMapping(xp, tau, tuple(range(9))).apply(p, line) - c)
        assert np.allclose((moved - r) / h, J_m[:, i], rtol=1e-4, atol=1e-5 * np.abs(J_m[:, i]).max()), i
    # The line moved by E a and tilted by E b (first order): offsets change by J_l (a, b).
    E = np.stack(perpendiculars(d[None, :]), axis=1)[0]
    a, b = np.array([1e-4, -2e-4]), np.array([3e-5, 1e-5])
    d2 = d + E.T @ b
    c2 = c + E.T @ a
    y = mapping.apply(p, line)
    s = (y - c) @ d
    moved = np.einsum("ni,ni->n", e, y - c2 - s[:, None] * (d2 - d))
    assert np.allclose(moved - r, J_l @ np.concatenate([a, b]), atol=1e-9)


def test_lines_add_information_to_the_used_hits_bound() -> None:
    motion, scene, sim, T = _truss()
    beam = beam_of_hits(scene, motion, sim.reference_m)
    faces = face_of_hits(scene, motion, sim.reference_m)
    used = fitted_hits(motion, scene, sim, T)
    info = line_information(motion, scene, sim, T, beam, ~used, two_d=False)
    assert np.allclose(info, info.T, atol=1e-9 * np.abs(info).max())
    assert np.linalg.eigvalsh(info)[0] >= -1e-9 * np.abs(info).max()
    plain = dense_bound(motion, scene, sim, T, hits=used, faces=faces)
    assert dense_bound(motion, scene, sim, T, hits=used, faces=faces, extra_information=np.zeros((9, 9))) == plain
    with_lines = dense_bound(motion, scene, sim, T, hits=used, faces=faces, extra_information=info)
    for key in ("spin_axis_deg", "spin_rate_deg_s", "precession_axis_deg", "precession_rate_deg_s"):
        assert with_lines[key] < plain[key], key


def test_the_wires_left_out_are_mostly_linear_cells() -> None:
    motion, scene, sim, T = _truss()
    noise = scene.scanner.noise
    data = dense_data(sim, T, noise.range_sigma_m)
    mapping = LineMapping(motion.at_reference(T).params(), data.tau_s, tuple(range(9)))
    surf = build_surfels(data, mapping, noise)
    planar_pt = surf.planar[surf.point_cell]
    cell_line, block_line, _ = classify(data, mapping, planar_pt, surf.planar, noise.range_sigma_m, 8.0)
    kept = np.ones(len(sim.xyz_m), dtype=bool) if data.kept is None else data.kept
    beam = beam_of_hits(scene, motion, sim.reference_m)[kept]
    wires_out = (beam >= 0) & ~planar_pt
    assert np.mean((cell_line | block_line)[wires_out]) >= 0.6
    # A line is never a planar surfel's point.
    assert not np.any((cell_line | block_line) & planar_pt)
