"""Triangle meshes built from boxes, with an albedo per triangle (the renderer's input)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray, IntArray

# The 12 triangles of a box over its 8 corners (corner i has bits x=i&1, y=i>>1&1, z=i>>2&1),
# wound outward.
_BOX_TRIANGLES = np.array(
    [[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
     [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]],
    dtype=np.int64,
)  # fmt: skip


@dataclass(frozen=True)
class Mesh:
    """Triangles over ``vertices_m`` (N, 3, body frame, metres); ``albedo`` (M,) per triangle."""

    vertices_m: FloatArray
    triangles: IntArray
    albedo: FloatArray

    @property
    def bounding_radius_m(self) -> float:
        """Radius of the sphere about the body origin that holds every vertex."""
        return float(np.max(np.linalg.norm(self.vertices_m, axis=1)))


def box(center_m: Sequence[float], size_m: Sequence[float], albedo: float, R: FloatArray | None = None) -> Mesh:
    """A box of edge lengths ``size_m`` along its own axes, rotated by ``R`` about the body origin after
    being centred at ``center_m`` (so ``R`` turns the whole placed box, as a hinge would)."""
    bits = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=float)
    v = np.asarray(center_m, dtype=float) + (bits - 0.5) * np.asarray(size_m, dtype=float)
    if R is not None:
        v = v @ np.asarray(R, dtype=float).T
    return Mesh(v, _BOX_TRIANGLES.copy(), np.full(12, float(albedo)))


def merge(meshes: Sequence[Mesh]) -> Mesh:
    """One mesh holding all of ``meshes``."""
    vertices, triangles, albedo = [], [], []
    offset = 0
    for m in meshes:
        vertices.append(m.vertices_m)
        triangles.append(m.triangles + offset)
        albedo.append(m.albedo)
        offset += len(m.vertices_m)
    return Mesh(np.vstack(vertices), np.vstack(triangles), np.concatenate(albedo))
