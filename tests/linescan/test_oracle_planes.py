"""The oracle-planes bench (``bench/linescan/oracle_planes.py``): a face's hits against its own
plane lie on it at the truth, their sigmas are the noise's, and the plane's offset and tilts are
projected off; the hits the fit holds are told from those it leaves out."""

from __future__ import annotations

import numpy as np
import pytest
from bench.linescan.dense_bound import face_of_hits, last_stage_matches
from bench.linescan.oracle_planes import held_hits, joined, oracle_rows, plane_rows
from bench.linescan.reuse_diag import at_truth

from tumblescan import Scanner, Scene
from tumblescan.linescan.dense.beams import find_beams
from tumblescan.linescan.dense.data import DenseData
from tumblescan.linescan.dense.mapping import LineMapping
from tumblescan.linescan.dense.matching import Linearized, robust_sigma
from tumblescan.linescan.dense.surfels import Surfels
from tumblescan.linescan.dense.terms import Terms
from tumblescan.linescan.sensor import perpendiculars

from ..conftest import motion_for

Box = tuple[Scene, DenseData, LineMapping, Surfels, np.ndarray, np.ndarray]


def _box(noise: bool) -> Box:
    motion = motion_for(1, distance_m=50.0)
    scene = Scene(scanner=Scanner(lines=160, pixels=160), noise=noise)
    sim, data, mapping, surf = at_truth(motion, scene, 1)
    kept = np.ones(len(sim.xyz_m), dtype=bool) if data.kept is None else data.kept
    face, normals = face_of_hits(scene, motion, sim.reference_m)
    return scene, data, mapping, surf, face[kept], normals


@pytest.mark.parametrize("noise", [False, True])
def test_a_faces_hits_lie_on_its_plane_within_their_noise(noise: bool) -> None:
    scene, data, mapping, _, face, normals = _box(noise)
    biggest = np.bincount(face[face >= 0]).argmax()
    hits = np.flatnonzero(face == biggest)
    lin = plane_rows(data, mapping, scene.scanner.noise, hits, normals[biggest])
    assert len(lin.r) == len(hits) > 1000 and lin.J.shape == (len(hits), 9)
    e = lin.r / np.sqrt(lin.var)
    if noise:
        # The sensor's variance along the face's normal is the rows' (three nuisances take ~nothing).
        assert 0.9 < np.sqrt(np.mean(e**2)) < 1.1
    else:
        # To the mesh's rounding (face_of_hits: the closest triangle in float32).
        assert np.max(np.abs(e)) < 1e-2
    # What is left is blind to the plane's offset and tilts: orthogonal to each in the weights.
    y = mapping.apply(data.xyz_m[hits], data.line[hits])
    e1, e2 = perpendiculars(normals[biggest][None, :])
    for column in (np.ones(len(y)), (y - y.mean(axis=0)) @ e1[0], (y - y.mean(axis=0)) @ e2[0]):
        assert abs(np.sum(column * lin.r / lin.var)) < 1e-8 * np.sum(np.abs(column * lin.r) / lin.var)


def test_the_fits_hits_are_held_and_only_the_rest_get_oracle_rows() -> None:
    scene, data, mapping, surf, face, normals = _box(True)
    noise = scene.scanner.noise
    matches, _ = last_stage_matches(data, mapping, surf, noise)
    terms = Terms(surf, matches, find_beams(data, mapping, surf, noise)).with_grazing(data, noise, mapping)
    held = held_hits(surf, terms)
    assert held[surf.point_cell == matches.src[0]].all() and held[terms.grazing.hit].all()
    assert 0.5 < held.mean() < 1.0
    rows = oracle_rows(data, mapping, noise, face, normals, ~held)
    assert 0 < len(rows.r) <= int((~held & (face >= 0)).sum())
    assert len(oracle_rows(data, mapping, noise, face, normals, np.zeros_like(held)).r) == 0


def test_the_extra_rows_are_weighed_at_the_pairs_scale() -> None:
    rng = np.random.default_rng(0)
    pairs = Linearized(rng.normal(0, 1.5, 4000), rng.normal(size=(4000, 9)), np.ones(4000))
    base = Linearized(np.r_[pairs.r, rng.normal(0, 9.0, 100)], rng.normal(size=(4100, 9)), np.ones(4100))
    extra = Linearized(rng.normal(0, 0.2, 3000), rng.normal(size=(3000, 9)), np.full(3000, 4.0))
    out = joined(base, extra, pairs)
    assert len(out.r) == 7100 and np.array_equal(out.var[:4100], base.var)
    e = out.r[4100:] / np.sqrt(out.var[4100:])
    assert np.isclose(robust_sigma(e), robust_sigma(pairs.r), rtol=1e-9)
    assert joined(base, Linearized(np.zeros(0), np.zeros((0, 9)), np.zeros(0)), pairs) is base
