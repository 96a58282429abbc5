"""The simulated target: a box bus, an instrument box on top and two unequal wings on thin yokes,
with its mass properties (for the torque-free flat spin about the major principal axis).

Body frame before centring: bus centre at the origin, wings along ±y, instrument on +z. ``solid``
moves the origin to the centre of mass.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray
from ..imaging.mesh import Mesh, box, merge

BUS_ALBEDO = 0.55
INSTRUMENT_ALBEDO = 0.70
PANEL_FRONT_ALBEDO = 0.24
PANEL_BACK_ALBEDO = 0.45
YOKE_ALBEDO = 0.35
BUS_DENSITY_KG_M3 = 150.0
PANEL_AREAL_KG_M2 = 12.0
YOKE_DENSITY_KG_M3 = 300.0


@dataclass(frozen=True)
class Part:
    """One solid box: centre, size, rotation (about the bus centre, as a hinge) and mass."""

    center_m: FloatArray
    size_m: FloatArray
    R: FloatArray
    mass_kg: float
    albedo: float


@dataclass(frozen=True)
class Target:
    """The centred mesh, its corners (body frame, m) and the major principal axis (body frame)."""

    mesh: Mesh
    corners_m: FloatArray
    major_axis_body: FloatArray
    inertia_kg_m2: FloatArray
    com_shift_m: FloatArray


def random_target(rng: np.random.Generator) -> Target:
    """Sizes from the digest: bus 1.3-2.1 x 1.2-1.8 x 1.5-2.4 m, wings 3-5 m (the other 70-90 %),
    1.2-2 m wide, 3 cm thick, 2-3 sub-panels with 5 cm gaps, drive angle ±25° about y."""
    bus = np.array([rng.uniform(1.3, 2.1), rng.uniform(1.2, 1.8), rng.uniform(1.5, 2.4)])
    inst = np.array([rng.uniform(0.4, 0.8), rng.uniform(0.4, 0.8), rng.uniform(0.3, 0.6)])
    yoke = float(rng.uniform(0.4, 0.8))
    long_m = float(rng.uniform(3.0, 5.0))
    lengths = (long_m, long_m * float(rng.uniform(0.7, 0.9)))
    width = float(rng.uniform(1.2, 2.0))
    n_sub = int(rng.integers(2, 4))
    drive = np.radians(rng.uniform(-25, 25))
    R_drive = np.array([[np.cos(drive), 0, np.sin(drive)], [0, 1, 0], [-np.sin(drive), 0, np.cos(drive)]])
    eye = np.eye(3)
    parts = [
        Part(np.zeros(3), bus, eye, float(np.prod(bus)) * BUS_DENSITY_KG_M3, BUS_ALBEDO),
        Part(np.array([0.0, 0.0, bus[2] / 2 + inst[2] / 2]), inst, eye, float(np.prod(inst)) * BUS_DENSITY_KG_M3,
             INSTRUMENT_ALBEDO),
    ]  # fmt: skip
    thickness, gap = 0.03, 0.05
    for side, length in zip((1.0, -1.0), lengths, strict=True):
        ysize = np.array([0.06, yoke, 0.06])
        parts.append(Part(np.array([0, side * (bus[1] + yoke) / 2, 0]), ysize, eye, float(np.prod(ysize)) *
                          YOKE_DENSITY_KG_M3, YOKE_ALBEDO))  # fmt: skip
        sub = (length - (n_sub - 1) * gap) / n_sub
        for k in range(n_sub):
            y = bus[1] / 2 + yoke + k * (sub + gap) + sub / 2
            size = np.array([width, sub, thickness])
            parts.append(Part(np.array([0, side * y, 0]), size, R_drive, width * sub * PANEL_AREAL_KG_M2,
                              PANEL_FRONT_ALBEDO))  # fmt: skip
    return _solid(parts)


def _solid(parts: list[Part]) -> Target:
    """Centre of mass, inertia tensor of the solid boxes and the mesh moved to the centre of mass."""
    mass = np.array([p.mass_kg for p in parts])
    centers = np.array([p.R @ p.center_m for p in parts])
    com = (mass[:, None] * centers).sum(axis=0) / mass.sum()
    inertia = np.zeros((3, 3))
    for p, c in zip(parts, centers, strict=True):
        a, b, h = p.size_m
        local = p.mass_kg / 12.0 * np.diag([b * b + h * h, a * a + h * h, a * a + b * b])
        d = c - com
        inertia += p.R @ local @ p.R.T + p.mass_kg * (d @ d * np.eye(3) - np.outer(d, d))
    evals, evecs = np.linalg.eigh(inertia)
    major = evecs[:, int(np.argmax(evals))]
    meshes, corners = [], []
    for p in parts:
        m = box((p.center_m - p.R.T @ com).tolist(), p.size_m.tolist(), p.albedo, p.R)
        if p.albedo == PANEL_FRONT_ALBEDO:  # the back face (-z of the panel) is brighter
            normals = _face_normals(m)
            back = normals @ (p.R @ np.array([0.0, 0.0, 1.0])) < -0.5
            m = Mesh(m.vertices_m, m.triangles, np.where(back, PANEL_BACK_ALBEDO, m.albedo))
        meshes.append(m)
        if p.mass_kg > 5.0:  # the yokes are too thin to be features
            corners.append(m.vertices_m)
    return Target(merge(meshes), np.vstack(corners), major, inertia, com)


def _face_normals(m: Mesh) -> FloatArray:
    v = m.vertices_m[m.triangles]
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    return np.asarray(n / np.linalg.norm(n, axis=1, keepdims=True), dtype=float)
