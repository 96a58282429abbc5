"""Cramer-Rao bound of the motion from dense frames of a target modelled as planes.

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

Faces of any shape (:func:`mesh_faces`): the shape's triangle mesh, its coplanar triangles
grouped into faces (region growing from the largest triangle: a triangle joins a face when
it shares a vertex with one of its triangles, its normal is within ``COPLANAR_DEG`` of the
face's and its vertices within ``COPLANAR_M`` of the face's plane; tested against the seed's
plane, not the neighbour's, so a finely tessellated curve cannot drift into one face). Each
hit is given the face of the triangle nearest to it (it lies on one: Open3D's closest-point
query returns the triangle's id). On the box this gives the box's 18 faces.
On curved tessellated surfaces (the cylinders of the telescope and the octagon, the dishes,
the Hubble mesh's tube) every flat facet is one face: the bound then credits the estimator
with the facet partition and with the facets being exactly flat, so it is the bound of an
estimator modelling the target as those planes, not of one fitting the true curved surface
(which would have fewer nuisance parameters: a cylinder has 5 for all its facets). A face
with fewer than ``MIN_FACE_POINTS`` hits fits its plane exactly (3 nuisance parameters) and
tells nothing about the motion: it is left out, as are hits on a degenerate (zero-area)
triangle, so that no near-singular face block enters the Schur complement.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypedDict, Unpack

import numpy as np
from numpy.typing import NDArray

from tumblescan import Motion, Scene
from tumblescan.geometry.rotations import axis_from_angles
from tumblescan.linescan.dense.data import DenseData
from tumblescan.linescan.dense.mapping import LineMapping
from tumblescan.linescan.dense.matching import Linearized, Matches, linearize, match
from tumblescan.linescan.dense.surfels import Surfels, build_surfels, normal_variance
from tumblescan.linescan.sensor import SensorNoise, perpendiculars
from tumblescan.linescan.simulate import FrameCloud
from tumblescan.linescan.validation import axis_sigma_rad
from tumblescan.target.motion import apply_rotation
from tumblescan.target.shape import SatelliteShape

from .truth import dense_data

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
# A hit belongs to a face when it lies within this of the face's plane (metres, body frame);
# the simulator casts in float32, a few micrometres at 100 m.
ON_FACE_M = 1e-4
# Triangles are one face when their planes agree this well (the brief's tight tolerance).
COPLANAR_DEG = 0.5
COPLANAR_M = 1e-3
# Vertices closer than this are one vertex (mesh files repeat a vertex per normal or UV).
SAME_VERTEX_M = 1e-6
# A face needs this many hits to say anything beyond its own plane's 3 parameters.
MIN_FACE_POINTS = 4
CHUNK = 200_000


def _body_frame(scene: Scene, motion: Motion, reference_m: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The hits in the body frame, ``(n, 3)``, and ``R_body_to_sensor``, ``(3, 3)``."""
    R = np.asarray(scene.R_body_to_sensor, dtype=float)
    origin = np.asarray(motion.center_m) + np.asarray(scene.body_offset_m)
    return (reference_m - origin) @ R, R  # R^T (p - origin), row-wise


def box_face_of_hits(scene: Scene, motion: Motion, reference_m: FloatArray) -> tuple[IntArray, FloatArray]:
    """The box satellite's faces from its boxes, ``6 * box + 2 * axis + side``: face index of
    each hit (``-1`` when none) and the faces' unit normals in the sensor frame, ``(18, 3)``.
    The reference the mesh faces of :func:`face_of_hits` are checked against."""
    if not isinstance(scene.shape, SatelliteShape):
        raise ValueError(f"box faces are those of the box satellite, not of {scene.shape.kind!r}")
    body, R = _body_frame(scene, motion, reference_m)
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


def normal_of_triangle(vertices_m: FloatArray, triangles: IntArray) -> FloatArray:
    """Unit normal of each triangle, ``(T, 3)``; zero for a degenerate (zero-area) one."""
    corners = vertices_m[triangles]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    twice_area = np.linalg.norm(cross, axis=1, keepdims=True)
    return np.asarray(np.where(twice_area > 1e-12, cross / np.maximum(twice_area, 1e-300), 0.0), dtype=float)


def mesh_faces(vertices_m: FloatArray, triangles: IntArray) -> tuple[IntArray, FloatArray]:
    """Coplanar triangles grouped into faces: the face of each triangle ``(T,)`` and the faces'
    unit normals ``(F, 3)`` (zero for a degenerate triangle, which is a face of its own).

    vertices_m: ``(V, 3)`` body frame; triangles: ``(T, 3)`` vertex indices.
    """
    corners = vertices_m[triangles]  # (T, 3 corners, 3)
    twice_area = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    normal = normal_of_triangle(vertices_m, triangles)
    flat = np.any(normal != 0, axis=1)
    # One id per vertex position, then each vertex's triangles (CSR).
    _, vid = np.unique(np.round(vertices_m / SAME_VERTEX_M), axis=0, return_inverse=True)
    tri_vid = vid.reshape(-1)[triangles]
    order = np.argsort(tri_vid.ravel(), kind="stable")
    bounds = np.searchsorted(tri_vid.ravel()[order], np.arange(vid.max() + 2))
    tri_of_vertex = order // 3
    cos_tol = np.cos(np.radians(COPLANAR_DEG))
    face = np.full(len(triangles), -1, dtype=np.int64)
    normals: list[FloatArray] = []
    for seed in np.argsort(-twice_area, kind="stable"):
        if face[seed] >= 0:
            continue
        f, n = len(normals), normal[seed]
        normals.append(n)
        face[seed] = f
        if not flat[seed]:
            continue
        offset = float(n @ corners[seed, 0])
        stack = [int(seed)]
        while stack:
            t = stack.pop()
            near = np.concatenate([tri_of_vertex[bounds[v] : bounds[v + 1]] for v in tri_vid[t]])
            near = near[face[near] < 0]
            near = near[
                (normal[near] @ n >= cos_tol) & np.all(np.abs(corners[near] @ n - offset) <= COPLANAR_M, axis=1)
            ]
            near = np.unique(near)
            face[near] = f
            stack += near.tolist()
    return face, np.asarray(normals, dtype=float).reshape(-1, 3)


def face_of_hits(scene: Scene, motion: Motion, reference_m: FloatArray) -> tuple[IntArray, FloatArray]:
    """Face index of each hit (``-1`` when on no face: off the mesh or on a degenerate
    triangle) and the faces' unit normals in the sensor frame at the reference time,
    ``(faces, 3)``; faces are the mesh's coplanar triangles (:func:`mesh_faces`)."""
    from tumblescan._open3d import load_open3d

    o3d = load_open3d()
    mesh = scene.shape.mesh()
    vertices = np.asarray(mesh.vertices, dtype=float)
    triangles = np.asarray(mesh.triangles, dtype=np.int64)
    tri_face, normals_body = mesh_faces(vertices, triangles)
    body, R = _body_frame(scene, motion, reference_m)
    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(o3d.core.Tensor(vertices.astype(np.float32)), o3d.core.Tensor(triangles.astype(np.uint32)))
    closest = rc.compute_closest_points(o3d.core.Tensor(body.astype(np.float32)), nthreads=0)
    triangle = closest["primitive_ids"].numpy().astype(np.int64)
    valid = triangle < len(triangles)
    triangle[~valid] = 0
    # Open3D's closest point is off by up to a millimetre on slender triangles (the 6 cm edges
    # of the box's panels), its triangle is right: the test is the distance to that triangle's
    # plane, in float64. Within a millimetre of an edge the neighbour face's triangle may come
    # back, on whose plane the hit also lies to a millimetre: no matter against 2 cm of noise.
    first = vertices[triangles[triangle, 0]]
    off = np.abs(np.einsum("ni,ni->n", body - first, normal_of_triangle(vertices, triangles)[triangle])) > COPLANAR_M
    face = np.where(off | ~valid, -1, tri_face[triangle])
    degenerate = ~np.any(normals_body != 0, axis=1)
    face[(face >= 0) & degenerate[np.maximum(face, 0)]] = -1
    return face.astype(np.int64), normals_body @ R.T


def majority_face(member_of: IntArray, face: IntArray, m: int) -> IntArray:
    """Each of ``m`` groups' most common face (the largest index among equals) over its members
    ``member_of`` ``(n,)`` whose ``face`` ``(n,)`` is known (``>= 0``); ``-1`` for a group with none."""
    ok = face >= 0
    pairs, counts = np.unique(np.column_stack([member_of[ok], face[ok]]), axis=0, return_counts=True)
    out = np.full(m, -1, dtype=np.int64)
    if len(pairs) == 0:
        return out
    order = np.lexsort((pairs[:, 1], counts, pairs[:, 0]))
    group = pairs[order, 0]
    last = np.r_[group[1:] != group[:-1], True]  # per group, the largest count (then face) sorts last
    out[group[last]] = pairs[order, 1][last]
    return out


def motion_sigmas_deg(x: np.ndarray, cov: np.ndarray) -> dict[str, float]:
    """The 1-sigma of the spin axis, spin rate, precession axis and precession rate (deg, deg/s)
    of the motion ``x`` with covariance ``cov`` (the motion's parameter order)."""
    deg = np.degrees
    return {
        "spin_axis": float(deg(axis_sigma_rad(x, cov, 0, 1))),
        "spin_rate": float(deg(np.sqrt(cov[2, 2]))),
        "precession_axis": float(deg(axis_sigma_rad(x, cov, 3, 4))),
        "precession_rate": float(deg(np.sqrt(cov[5, 5]))),
    }


@dataclass(frozen=True)
class BoundCovariances:
    """The motion's parameters at ``T`` (order of :meth:`Motion.params`) and two ``(9, 9)``
    Cramer-Rao covariances of them: ``facets``, every face's plane a nuisance (the bound of an
    estimator that models the target as planes), and ``known_shape``, the whole shape known and
    only its pose at ``T`` a nuisance (6 parameters: the bound of any estimator, even one given
    the target's exact model)."""

    x: FloatArray
    facets: FloatArray
    known_shape: FloatArray
    points: int
    faces: int


class BoundInputs(TypedDict, total=False):
    """The optional inputs of :func:`bound_covariances` (see there)."""

    hits: NDArray[np.bool_] | None
    faces: tuple[IntArray, FloatArray] | None
    extra_information: FloatArray | None


def dense_bound(
    motion: Motion, scene: Scene, sim: FrameCloud, reference_time_s: float, **inputs: Unpack[BoundInputs]
) -> dict[str, float]:
    """1-sigma bounds at the truth (the noise-free hits, or only ``hits``), in the result's units,
    of an estimator that models the target as planes (see :func:`bound_covariances`)."""
    b = bound_covariances(motion, scene, sim, reference_time_s, **inputs)
    return {
        **bound_sigmas(b.x, b.facets),
        "center_m": float(np.sqrt(np.trace(b.facets[6:9, 6:9]))),
        "points": b.points,
        "faces": b.faces,
    }


def bound_sigmas(x: FloatArray, cov: FloatArray) -> dict[str, float]:
    """:func:`motion_sigmas_deg` keyed with the result's units (``spin_axis_deg``, ``spin_rate_deg_s``, ...)."""
    return {f"{k}_deg_s" if k.endswith("rate") else f"{k}_deg": v for k, v in motion_sigmas_deg(x, cov).items()}


def bound_covariances(
    motion: Motion,
    scene: Scene,
    sim: FrameCloud,
    reference_time_s: float,
    *,
    hits: NDArray[np.bool_] | None = None,
    faces: tuple[IntArray, FloatArray] | None = None,
    extra_information: FloatArray | None = None,
) -> BoundCovariances:
    """The bounds at the truth (the noise-free hits, or only ``hits``).

    faces: each hit's face and the faces' sensor-frame normals; by default the mesh's
    coplanar triangles (:func:`face_of_hits`). extra_information: ``(9, 9)`` Fisher information
    on the motion (at ``T``, parameter order of :meth:`Motion.params`, its own nuisances already
    eliminated) of other hits, added before the inversion (``bench/linescan/line_potential.py``'s
    beams modelled as lines); to the facets' bound only.
    """
    truth = motion.at_reference(reference_time_s)
    x = truth.params()
    face, normals = faces if faces is not None else face_of_hits(scene, motion, sim.reference_m)
    n_faces = len(normals)
    # The simulator's faces and reference points are at the motion's own reference time; the
    # planes solved for are those at T, which the motion turns them into. (Normals at the wrong
    # time gave rate bounds 30-45 % apart at T a few seconds apart; the rates' bound does not
    # depend on T.)
    tau_s = reference_time_s - motion.reference_time_s
    normals = np.asarray(apply_rotation(motion.params(), np.full(n_faces, tau_s), normals), dtype=float)
    keep = face >= 0 if hits is None else (face >= 0) & hits
    # Too few hits to pin a face's plane: they fit it exactly and say nothing of the motion.
    counts = np.bincount(face[keep], minlength=n_faces)
    keep &= counts[np.maximum(face, 0)] >= MIN_FACE_POINTS
    xyz, face = sim.xyz_true_m[keep], face[keep]
    line_key = sim.frame[keep].astype(np.int64) * scene.scanner.lines + sim.line[keep]
    _, first, line = np.unique(line_key, return_index=True, return_inverse=True)
    tau = sim.t_s[keep][first] - reference_time_s
    mapping = LineMapping(x, tau, tuple(range(9)))
    ref = motion.position(sim.reference_m[keep], np.full(len(xyz), reference_time_s))
    counts = np.bincount(face, minlength=n_faces)
    sums = np.stack([np.bincount(face, weights=ref[:, k], minlength=n_faces) for k in range(3)], axis=1)
    centres = np.asarray(sums / np.maximum(counts, 1)[:, None], dtype=float)
    tangents = np.stack(perpendiculars(np.where(counts[:, None] > 0, normals, [1.0, 0.0, 0.0])), axis=1)
    F_mm = np.zeros((9, 9))
    F_mf = np.zeros((n_faces, 9, 3))
    F_ff = np.zeros((n_faces, 3, 3))
    # The known shape's pose at T: a small turn dtheta about ``origin`` and a shift dt move the
    # residual by ``(n x (y - origin)) . dtheta - n . dt``.
    origin = ref.mean(axis=0)
    F_mp = np.zeros((9, 6))
    F_pp = np.zeros((6, 6))
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
        J_p = np.concatenate([np.cross(n, y + centres[fc] - origin), -n], axis=1)
        F_mp += (J_m * w[:, None]).T @ J_p
        F_pp += (J_p * w[:, None]).T @ J_p
        # Per-face sums of the outer products, one bincount per entry (thousands of faces).
        for j in range(3):
            wj = w * J_f[:, j]
            for i in range(9):
                F_mf[:, i, j] += np.bincount(fc, weights=wj * J_m[:, i], minlength=n_faces)
            for k in range(j, 3):
                F_ff[:, j, k] += np.bincount(fc, weights=wj * J_f[:, k], minlength=n_faces)
    F_ff = np.triu(F_ff) + np.transpose(np.triu(F_ff, 1), (0, 2, 1))
    used = np.flatnonzero(counts > 0)
    # pinv: the hits of a face along one scan line leave its tilt about that line free (no
    # information there, and none lost on the motion: the line moves rigidly).
    absorbed = np.einsum("fij,fjk,flk->il", F_mf[used], np.linalg.pinv(F_ff[used], rcond=1e-10, hermitian=True),
                         F_mf[used])  # fmt: skip
    extra = np.zeros((9, 9)) if extra_information is None else extra_information
    return BoundCovariances(
        x=np.asarray(x, dtype=float),
        facets=np.asarray(np.linalg.inv(F_mm - absorbed + extra), dtype=np.float64),
        # pinv: a part of revolution alone (a tube, a dish) leaves its turn about its axis free.
        known_shape=np.asarray(
            np.linalg.inv(F_mm - F_mp @ np.linalg.pinv(F_pp, rcond=1e-10, hermitian=True) @ F_mp.T), dtype=np.float64
        ),
        points=len(xyz),
        faces=len(used),
    )


def share_within(
    x: FloatArray, cov: FloatArray, axis_limit_deg: float, rate_limit_deg_s: float, draws: int = 20_000
) -> float:
    """Probability that an unbiased estimate of covariance ``cov`` about the truth ``x`` has both
    axes within ``axis_limit_deg`` (angle to the true axis) and both rates within
    ``rate_limit_deg_s``: what an efficient estimator would score against those limits."""
    rng = np.random.default_rng(0)
    xs = rng.multivariate_normal(x, cov, size=draws, method="eigh")
    ok = np.ones(draws, dtype=bool)
    for a, b, rate in ((0, 1, 2), (3, 4, 5)):
        cos = axis_from_angles(xs[:, a], xs[:, b]) @ axis_from_angles(x[a], x[b])
        ok &= np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))) <= axis_limit_deg
        ok &= np.degrees(np.abs(xs[:, rate] - x[rate])) <= rate_limit_deg_s
    return float(ok.mean())


def fitted_hits(motion: Motion, scene: Scene, sim: FrameCloud, reference_time_s: float) -> NDArray[np.bool_]:
    """The hits the dense fit can use: those in planar surfels, built as the estimator builds
    them (cells of its size) at the true motion, with the points of cells across edges handed to
    their faces' surfels. The rest lie along edges of faces and of the view, or on booms."""
    noise = scene.scanner.noise
    data = dense_data(sim, reference_time_s, noise.range_sigma_m)
    mapping = LineMapping(motion.at_reference(reference_time_s).params(), data.tau_s, tuple(range(9)))
    used = np.zeros(len(sim.xyz_m), dtype=bool)
    kept = np.ones(len(used), dtype=bool) if data.kept is None else data.kept
    surf = build_surfels(data, mapping, noise)
    used[kept] = surf.planar[surf.point_cell]  # with the points handed over to their faces' surfels
    return used


def last_stage_matches(
    data: DenseData, mapping: LineMapping, surf: Surfels, noise: SensorNoise
) -> tuple[Matches, Linearized]:
    """The refinement's last stage again at ``mapping``: every planar surfel matched in every other
    frame with the tightest gate, and the residuals linearised."""
    cells = np.flatnonzero(surf.planar)
    F = data.n_frames
    own = data.cell_frame[cells]
    src = np.repeat(cells, F - 1)
    partner = ((own[:, None] + np.arange(1, F)[None, :]) % F).ravel()
    gate = max(5 * noise.range_sigma_m, 1.5 * data.surfel_m)
    mt = match(data, mapping, surf, src, partner, gate)
    return mt, linearize(data, mapping, surf, mt, noise)
