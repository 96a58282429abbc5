"""Cramer-Rao bound of the motion from dense frames of a piecewise-planar target.

The bench's reference for what dense frames can deliver, the counterpart of the corner-track
bound in ``bench/accuracy.py``. Each simulated hit lies on one face ``f`` of the target, a
plane with unit normal ``n_f`` through ``c_f`` at the reference time ``T``. The measured point
``x`` of a line at ``tau = t - T``, mapped to ``T`` by the motion ``M`` (9 parameters), obeys

    r = n_f . (M(x; tau) - c_f) - d_f,    Var r = n_t^T Sigma(x) n_t,   n_t = R(tau) n_f

with ``Sigma`` the sensor's range and angle noise. The shape is unknown to an estimator, so
every face's plane is a nuisance: a tilt of ``n_f`` (2 parameters) and an offset ``d_f``. The
bound on the motion is the inverse of the Schur complement of the faces' block of the Fisher
information ``sum J^T J / Var r``. It credits the estimator with knowing which face each
point is on, and ignores edges and silhouettes (which carry little at 2 cm of range noise),
so no estimator that models the target as planes does better.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from tumblescan import Motion, Scene
from tumblescan.linescan.dense.estimate import SURFEL_FRACTION
from tumblescan.linescan.dense.registration import extent_m
from tumblescan.linescan.dense.surfels import LineMapping, build_surfels, normal_variance, prepare
from tumblescan.linescan.sensor import perpendiculars
from tumblescan.linescan.simulate import FrameCloud
from tumblescan.linescan.validation import axis_sigma_rad
from tumblescan.target.shape import SatelliteShape

FloatArray = NDArray[np.float64]
# A hit belongs to a face when it lies within this of the face's plane (metres, body frame).
ON_FACE_M = 1e-4
CHUNK = 200_000


def face_of_hits(scene: Scene, motion: Motion, reference_m: FloatArray) -> tuple[NDArray[np.int64], FloatArray]:
    """Face index of each hit (``-1`` when none) and the faces' unit normals in the sensor
    frame at the reference time, ``(faces, 3)``; faces are ``6 * box + 2 * axis + side``."""
    R = np.asarray(scene.R_body_to_sensor, dtype=float)
    origin = np.asarray(motion.center_m) + np.asarray(scene.body_offset_m)
    body = (reference_m - origin) @ R  # R^T (p - origin), row-wise
    if not isinstance(scene.shape, SatelliteShape):
        raise ValueError(f"the dense bound is computed for the box satellite only, not {scene.shape.kind!r}")
    boxes = scene.shape.boxes()
    face = np.full(len(body), -1, dtype=np.int64)
    normals = np.zeros((6 * len(boxes), 3))
    for b, (lo, hi) in enumerate(boxes):
        inside = np.all((body >= lo - ON_FACE_M) & (body <= hi + ON_FACE_M), axis=1)
        for axis in range(3):
            for side, bound in enumerate((lo[axis], hi[axis])):
                f = 6 * b + 2 * axis + side
                normals[f] = R[:, axis] * (1.0 if side else -1.0)
                on = inside & (np.abs(body[:, axis] - bound) < ON_FACE_M) & (face < 0)
                face[on] = f
    return face, normals


def dense_bound(
    motion: Motion, scene: Scene, sim: FrameCloud, reference_time_s: float, *, hits: NDArray[np.bool_] | None = None
) -> dict[str, float]:
    """1-sigma bounds at the truth (the noise-free hits, or only ``hits``), in the result's units."""
    truth = motion.at_reference(reference_time_s)
    x = truth.params()
    face, normals = face_of_hits(scene, motion, sim.reference_m)
    keep = face >= 0 if hits is None else (face >= 0) & hits
    xyz, face = sim.xyz_true_m[keep], face[keep]
    line_key = sim.frame[keep].astype(np.int64) * scene.scanner.lines + sim.line[keep]
    _, first, line = np.unique(line_key, return_index=True, return_inverse=True)
    tau = sim.t_s[keep][first] - reference_time_s
    mapping = LineMapping(x, tau, tuple(range(9)))
    n_faces = len(normals)
    ref = sim.reference_m[keep]
    centres = np.array([ref[face == f].mean(axis=0) if np.any(face == f) else np.zeros(3) for f in range(n_faces)])
    tangents = np.stack(perpendiculars(normals), axis=1)  # (faces, 2, 3)
    F_mm = np.zeros((9, 9))
    F_mf = np.zeros((n_faces, 9, 3))
    F_ff = np.zeros((n_faces, 3, 3))
    for start in range(0, len(xyz), CHUNK):
        sl = slice(start, start + CHUNK)
        p, ln, fc = xyz[sl], line[sl], face[sl]
        n = normals[fc]
        J_m = mapping.normal_derivative(n, p, ln)
        n_t = np.einsum("nab,na->nb", mapping.Rt[ln], n)  # R(tau) n
        w = 1.0 / normal_variance(scene.scanner.noise, p, n_t)
        y = mapping.apply(p, ln) - centres[fc]
        # The plane's tilt along its two tangents, and its offset.
        tilt = np.einsum("nki,ni->nk", tangents[fc], y)
        J_f = np.concatenate([tilt, -np.ones((len(y), 1))], axis=1)
        F_mm += (J_m * w[:, None]).T @ J_m
        for f in np.unique(fc):
            s = fc == f
            F_mf[f] += (J_m[s] * w[s, None]).T @ J_f[s]
            F_ff[f] += (J_f[s] * w[s, None]).T @ J_f[s]
    schur = F_mm.copy()
    for f in range(n_faces):
        # pinv: a face hit by a point or two fits its own plane and tells nothing.
        schur -= F_mf[f] @ np.linalg.pinv(F_ff[f], rcond=1e-10, hermitian=True) @ F_mf[f].T
    cov = np.asarray(np.linalg.inv(schur), dtype=np.float64)
    deg = np.degrees
    return {
        "spin_axis_deg": float(deg(axis_sigma_rad(x, cov, 0, 1))),
        "spin_rate_deg_s": float(deg(np.sqrt(cov[2, 2]))),
        "precession_axis_deg": float(deg(axis_sigma_rad(x, cov, 3, 4))),
        "precession_rate_deg_s": float(deg(np.sqrt(cov[5, 5]))),
        "center_m": float(np.sqrt(np.trace(cov[6:9, 6:9]))),
        "points": len(xyz),
        "faces": int(np.count_nonzero(np.any(F_ff != 0, axis=(1, 2)))),
    }


def fitted_hits(motion: Motion, scene: Scene, sim: FrameCloud, reference_time_s: float) -> NDArray[np.bool_]:
    """The hits the dense fit can use: those in planar surfels, built as the estimator builds
    them (cells of extent / 100) at the true motion. The rest lie near edges of faces and of
    the view, where a cell may straddle two faces."""
    frame = sim.frame.astype(np.int64)
    per_frame = [sim.xyz_m[frame == f] for f in range(int(frame.max()) + 1)]
    tau = sim.t_s - reference_time_s
    noise = scene.scanner.noise
    data = prepare(
        sim.xyz_m, tau, frame, surfel_m=extent_m(per_frame) * SURFEL_FRACTION, range_sigma_m=noise.range_sigma_m
    )
    mapping = LineMapping(motion.at_reference(reference_time_s).params(), data.tau_s, tuple(range(9)))
    used = np.zeros(len(sim.xyz_m), dtype=bool)
    kept = np.ones(len(used), dtype=bool) if data.kept is None else data.kept
    used[kept] = build_surfels(data, mapping, noise).planar[data.cell]
    return used
