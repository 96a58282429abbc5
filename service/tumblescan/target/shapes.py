"""A library of spacecraft shapes beside the box satellite, for simulating real geometry:
curved tubes, dishes, long thin booms and trusses, one-sided arrays, and any mesh file.

Each shape is a small pydantic model (dimensions in metres, ``kind`` naming it) with the same
three methods as :class:`~tumblescan.target.shape.SatelliteShape`: ``mesh()`` (one Open3D
triangle mesh in the body frame), ``corners_m()`` (salient points used as tracked features:
box corners, dish rims, boom tips) and ``extent_m()``. Parametric parts are built from
boxes, closed cylinders, paraboloid dish shells and thin beams.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Discriminator, Field, Tag

from .._open3d import load_open3d
from .._typing import FloatArray
from ..errors import MalformedInputError
from ..geometry.rotations import tangent_basis
from .shape import SatelliteShape

if TYPE_CHECKING:
    import open3d as o3d


class _Parts:
    """A mesh under construction and its feature points."""

    def __init__(self) -> None:
        self.mesh = load_open3d().geometry.TriangleMesh()
        self.features: list[FloatArray] = []

    def box(self, lo: Any, hi: Any, *, features: bool = True) -> None:
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        box = load_open3d().geometry.TriangleMesh.create_box(*(hi - lo))
        self.mesh += box.translate(lo)
        if features:
            self.features += [
                np.array([x, y, z]) for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])
            ]

    def cylinder(self, radius_m: float, length_m: float, axis: Any, center: Any, resolution: int = 48) -> None:
        o3d = load_open3d()
        cyl = o3d.geometry.TriangleMesh.create_cylinder(radius=radius_m, height=length_m, resolution=resolution)
        R = _rotation_z_to(np.asarray(axis, float))
        self.mesh += cyl.rotate(R, center=(0, 0, 0)).translate(np.asarray(center, float))
        a = R[:, 2]
        for end in (-0.5, 0.5):  # four rim points at each end
            for u in (R[:, 0], R[:, 1], -R[:, 0], -R[:, 1]):
                self.features.append(np.asarray(center, float) + end * length_m * a + radius_m * u)

    def dish(self, radius_m: float, depth_m: float, axis: Any, vertex: Any, rings: int = 12, sectors: int = 48) -> None:
        """A paraboloid shell ``z = depth (r / radius)^2`` opening along ``axis`` from ``vertex``."""
        o3d = load_open3d()
        r = np.linspace(0.0, radius_m, rings + 1)[1:]
        phi = np.linspace(0.0, 2 * np.pi, sectors, endpoint=False)
        rr, pp = np.meshgrid(r, phi, indexing="ij")
        pts = np.stack([rr * np.cos(pp), rr * np.sin(pp), depth_m * (rr / radius_m) ** 2], axis=-1).reshape(-1, 3)
        verts = np.vstack([[0.0, 0.0, 0.0], pts])
        tris = [[0, 1 + s, 1 + (s + 1) % sectors] for s in range(sectors)]
        for i in range(rings - 1):
            for s in range(sectors):
                a, b = 1 + i * sectors + s, 1 + i * sectors + (s + 1) % sectors
                tris += [[a, a + sectors, b], [b, a + sectors, b + sectors]]
        R = _rotation_z_to(np.asarray(axis, float))
        shell = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(verts @ R.T + np.asarray(vertex, float)),
                                          o3d.utility.Vector3iVector(np.asarray(tris, dtype=np.int32)))  # fmt: skip
        self.mesh += shell
        rim = verts[1 + (rings - 1) * sectors :: sectors // 4][:4]
        self.features += list(rim @ R.T + np.asarray(vertex, float))

    def beam(self, p0: Any, p1: Any, width_m: float, *, features: bool = True) -> None:
        """A thin square beam from ``p0`` to ``p1``."""
        o3d = load_open3d()
        p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
        length = float(np.linalg.norm(p1 - p0))
        box = o3d.geometry.TriangleMesh.create_box(width_m, width_m, length)
        box.translate((-width_m / 2, -width_m / 2, 0.0))
        self.mesh += box.rotate(_rotation_z_to(p1 - p0), center=(0, 0, 0)).translate(p0)
        if features:
            self.features += [p0, p1]

    def plate(self, center: Any, u: Any, v: Any, size_u_m: float, size_v_m: float, thickness_m: float) -> None:
        """A flat panel spanned by unit directions ``u`` and ``v`` about ``center``."""
        o3d = load_open3d()
        u, v = np.asarray(u, float), np.asarray(v, float)
        n = np.cross(u, v)
        box = o3d.geometry.TriangleMesh.create_box(size_u_m, size_v_m, thickness_m)
        box.translate((-size_u_m / 2, -size_v_m / 2, -thickness_m / 2))
        R = np.column_stack([u, v, n])
        self.mesh += box.rotate(R, center=(0, 0, 0)).translate(np.asarray(center, float))
        self.features += [np.asarray(center, float) + a * size_u_m / 2 * u + b * size_v_m / 2 * v
                          for a in (-1, 1) for b in (-1, 1)]  # fmt: skip

    def corners(self) -> FloatArray:
        return np.asarray(self.features, dtype=float)


def _rotation_z_to(axis: FloatArray) -> FloatArray:
    """A rotation taking ``+z`` to ``axis`` (columns: two perpendicular unit vectors and the axis)."""
    a = axis / np.linalg.norm(axis)
    e1, e2 = tangent_basis(a)
    return np.column_stack([-e1, -e2, a])  # the sense the library's meshes were built with


def _bus(bus_m: tuple[float, float, float]) -> tuple[_Parts, tuple[float, float, float]]:
    """A new shape with a box bus centred at the origin, and the bus's half sizes."""
    half = (bus_m[0] / 2, bus_m[1] / 2, bus_m[2] / 2)
    p = _Parts()
    p.box(tuple(-h for h in half), half)
    return p, half


class _Parametric(BaseModel, ABC):
    model_config = ConfigDict(extra="forbid", frozen=True)

    @abstractmethod
    def build(self) -> _Parts:
        """The shape's mesh and features, part by part."""

    def mesh(self) -> o3d.geometry.TriangleMesh:
        return self.build().mesh

    def corners_m(self) -> FloatArray:
        return self.build().corners()

    def extent_m(self) -> FloatArray:
        bounds = self.build().mesh.get_axis_aligned_bounding_box()
        return np.asarray(bounds.get_extent(), dtype=float)


class TelescopeShape(_Parametric):
    """A telescope tube with its aperture door open, two solar wings and two dishes on booms."""

    kind: Literal["telescope"] = "telescope"
    tube_radius_m: float = Field(2.1, gt=0)
    tube_length_m: float = Field(13.2, gt=0)
    wing_m: tuple[float, float] = (5.0, 2.5)
    dish_radius_m: float = Field(0.9, gt=0)

    def build(self) -> _Parts:
        p, R, L = _Parts(), self.tube_radius_m, self.tube_length_m
        p.cylinder(R, L, (0, 0, 1), (0, 0, 0))
        # Aperture door, hinged at the tube's rim and open 110 degrees.
        door_c = np.array([0.0, R + R * np.cos(np.radians(70)), L / 2 + R * np.sin(np.radians(70))])
        p.plate(door_c, (1, 0, 0), (0, -np.cos(np.radians(70)), -np.sin(np.radians(70))), 2 * R, 2 * R, 0.08)
        for side in (-1, 1):
            p.plate((0, side * (R + 0.3 + self.wing_m[0] / 2), 0), (0, 1, 0), (0, 0, 1), *self.wing_m, 0.04)
            boom_end = np.array([side * (R + 3.5), 0.0, -L / 4])
            p.beam((side * R, 0, -L / 4), boom_end, 0.12)
            p.dish(self.dish_radius_m, 0.3, (side, 0, 0.3), boom_end)
        return p


class DishBoomShape(_Parametric):
    """A bus with two large parabolic dishes and a long thin boom."""

    kind: Literal["dish-boom"] = "dish-boom"
    bus_m: tuple[float, float, float] = (2.6, 2.6, 3.2)
    dish_radii_m: tuple[float, float] = (2.4, 1.7)
    boom_length_m: float = Field(10.0, gt=0)
    boom_width_m: float = Field(0.1, gt=0)

    def build(self) -> _Parts:
        p, (bx, by, bz) = _bus(self.bus_m)
        p.dish(self.dish_radii_m[0], 0.55, (0, 0.3, 1), (0, 0, bz + 0.4))
        p.beam((0, 0, bz), (0, 0, bz + 0.4), 0.2, features=False)
        p.dish(self.dish_radii_m[1], 0.4, (0, 1, 0), (0, by + 0.5, 0))
        p.beam((0, by, 0), (0, by + 0.5, 0), 0.2, features=False)
        p.beam((bx, 0, 0), (bx + self.boom_length_m, 0, 0), self.boom_width_m)
        return p


class LongArrayShape(_Parametric):
    """A bus with one long single-sided solar array on a yoke."""

    kind: Literal["long-array"] = "long-array"
    bus_m: tuple[float, float, float] = (2.0, 2.0, 3.0)
    array_m: tuple[float, float] = (15.0, 3.0)
    yoke_m: float = Field(1.2, gt=0)

    def build(self) -> _Parts:
        p, (bx, _, _) = _bus(self.bus_m)
        p.beam((bx, 0, 0), (bx + self.yoke_m, 0, 0), 0.15)
        start = bx + self.yoke_m
        p.plate((start + self.array_m[0] / 2, 0, 0), (1, 0, 0), (0, 1, 0), *self.array_m, 0.05)
        return p


class OctagonTrussShape(_Parametric):
    """An octagonal bus with four flat panels and a thin wire truss tower."""

    kind: Literal["octagon-truss"] = "octagon-truss"
    bus_radius_m: float = Field(1.6, gt=0)
    bus_height_m: float = Field(3.0, gt=0)
    panel_m: tuple[float, float] = (4.0, 2.0)
    truss_length_m: float = Field(6.0, gt=0)
    wire_m: float = Field(0.04, gt=0)

    def build(self) -> _Parts:
        p = _Parts()
        p.cylinder(self.bus_radius_m, self.bus_height_m, (0, 0, 1), (0, 0, 0), resolution=8)
        for k in range(4):
            u = np.array([np.cos(k * np.pi / 2), np.sin(k * np.pi / 2), 0.0])
            center = (self.bus_radius_m + 0.2 + self.panel_m[0] / 2) * u
            p.plate(center, u, (0, 0, 1), *self.panel_m, 0.04)
        # A square lattice tower on the top face: four longerons, rings and diagonals every metre.
        h0, a = self.bus_height_m / 2, 0.5
        legs = [np.array([sx * a, sy * a, 0.0]) for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1))]
        top = np.array([0.0, 0.0, h0 + self.truss_length_m])
        for leg in legs:
            p.beam(leg + [0, 0, h0], leg + top, self.wire_m)
        bays = max(1, round(self.truss_length_m))
        for i in range(bays + 1):
            z = h0 + self.truss_length_m * i / bays
            for j in range(4):
                p.beam(legs[j] + [0, 0, z], legs[(j + 1) % 4] + [0, 0, z], self.wire_m, features=False)
                if i < bays:
                    z2 = h0 + self.truss_length_m * (i + 1) / bays
                    p.beam(legs[j] + [0, 0, z], legs[(j + 1) % 4] + [0, 0, z2], self.wire_m, features=False)
        return p


class MeshFileShape(BaseModel):
    """Any mesh Open3D reads (GLB, glTF, OBJ, PLY, STL), scaled so its largest bounding-box side
    is ``size_m`` and centred at its area-weighted surface centroid."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    kind: Literal["mesh"] = "mesh"
    path: str
    size_m: float = Field(gt=0)
    features: int = Field(24, ge=4, le=1000, description="salient vertices used as tracked features")

    @cached_property
    def _mesh(self) -> o3d.geometry.TriangleMesh:
        o3d = load_open3d()
        if not Path(self.path).is_file():
            raise MalformedInputError(f"no such mesh file: {self.path}", field="mesh")
        mesh = o3d.io.read_triangle_mesh(self.path)
        if len(mesh.triangles) == 0:
            raise MalformedInputError(f"{self.path} has no triangles Open3D can read", field="mesh")
        verts = np.asarray(mesh.vertices)
        if not np.isfinite(verts).all():
            raise MalformedInputError(f"{self.path}: a vertex has a NaN or infinite coordinate", field="mesh")
        tri = np.asarray(mesh.triangles)
        a, b, c = verts[tri[:, 0]], verts[tri[:, 1]], verts[tri[:, 2]]
        area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
        if not area.sum() > 0:
            raise MalformedInputError(f"{self.path}: every triangle has zero area (a degenerate mesh)", field="mesh")
        centroid = (area[:, None] * (a + b + c) / 3).sum(axis=0) / area.sum()
        scale = self.size_m / float(np.max(np.ptp(verts, axis=0)))
        mesh.vertices = o3d.utility.Vector3dVector((verts - centroid) * scale)
        return mesh

    def mesh(self) -> o3d.geometry.TriangleMesh:
        return load_open3d().geometry.TriangleMesh(self._mesh)

    def corners_m(self) -> FloatArray:
        """Farthest-point samples of the vertices, starting from the one farthest from the centre."""
        verts = np.asarray(self._mesh.vertices)
        chosen = [int(np.argmax(np.linalg.norm(verts, axis=1)))]
        dist = np.linalg.norm(verts - verts[chosen[0]], axis=1)
        while len(chosen) < min(self.features, len(verts)):
            chosen.append(int(np.argmax(dist)))
            dist = np.minimum(dist, np.linalg.norm(verts - verts[chosen[-1]], axis=1))
        return np.asarray(verts[chosen], dtype=float)

    def extent_m(self) -> FloatArray:
        return np.asarray(np.ptp(np.asarray(self._mesh.vertices), axis=0), dtype=float)


PARAMETRIC: dict[str, type[_Parametric]] = {
    "telescope": TelescopeShape,
    "dish-boom": DishBoomShape,
    "long-array": LongArrayShape,
    "octagon-truss": OctagonTrussShape,
}


def _kind_of(value: Any) -> str:
    """The shape's ``kind``; ``box`` when absent (scenes written before the library existed)."""
    kind = value.get("kind", "box") if isinstance(value, dict) else getattr(value, "kind", "box")
    return str(kind)


Shape = Annotated[
    Annotated[SatelliteShape, Tag("box")]
    | Annotated[TelescopeShape, Tag("telescope")]
    | Annotated[DishBoomShape, Tag("dish-boom")]
    | Annotated[LongArrayShape, Tag("long-array")]
    | Annotated[OctagonTrussShape, Tag("octagon-truss")]
    | Annotated[MeshFileShape, Tag("mesh")],
    Discriminator(_kind_of),
]
SHAPE_NAMES = ("box", *PARAMETRIC, "mesh")
