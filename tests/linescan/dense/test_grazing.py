"""The grazing hits' groups (``dense.grazing``) and the terms they join (``dense.terms``): on their
targets' planes at grazing incidence, the same groups as the bench's, their Jacobian, the hits
left to the members kept out, and the rows of every kind in one order at one scale."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from bench.linescan.hit_pairs import linearize_hits, match_hits
from bench.linescan.reuse_diag import at_truth

from tumblescan import Scanner, Scene
from tumblescan.linescan.dense.beams import Beams
from tumblescan.linescan.dense.data import DenseData
from tumblescan.linescan.dense.grazing import MAX_COS_INCIDENCE, Grazing, find_grazing, grazing_rows
from tumblescan.linescan.dense.mapping import LineMapping
from tumblescan.linescan.dense.matching import match, partners, robust_sigma
from tumblescan.linescan.dense.surfels import Surfels
from tumblescan.linescan.dense.terms import Terms
from tumblescan.linescan.sensor import SensorNoise

from ...conftest import motion_for

Case = tuple[DenseData, LineMapping, Surfels, SensorNoise]


def _box(noise: bool) -> Case:
    motion = motion_for(1, distance_m=50.0)
    scene = Scene(scanner=Scanner(lines=160, pixels=160), noise=noise)
    _, data, mapping, surf = at_truth(motion, scene, 1)
    return data, mapping, surf, scene.scanner.noise


@pytest.fixture(scope="module")
def noise_free() -> Case:
    return _box(noise=False)


@pytest.fixture(scope="module")
def noisy() -> Case:
    return _box(noise=True)


def test_on_noise_free_frames_the_groups_lie_on_their_targets_planes_at_grazing_incidence(noise_free: Case) -> None:
    data, mapping, surf, noise = noise_free
    groups = find_grazing(data, mapping, surf, noise)
    assert groups.groups > 100 and groups.hits > 0.005 * len(data.xyz_m)
    # Each group's hits are outside every planar surfel and its target is a planar surfel of
    # another frame.
    assert np.all(surf.planar[groups.target])
    assert np.all(data.cell_frame[groups.target] != data.cell_frame[groups.cell])
    assert not np.any(surf.planar[surf.point_cell[groups.hit]])
    # ... and in a cell the build handed none of to a planar neighbour: a whole cell's hits.
    handed = np.unique(data.cell[surf.point_cell != data.cell])
    assert len(handed) > 0 and not np.any(np.isin(data.cell[groups.hit], handed))
    r, J, var = grazing_rows(groups, surf, mapping, noise)
    assert J is not None and np.all(var > 0)
    # The box's faces are exact planes: the groups lie on their targets' planes within what the
    # surfels' build leaves (their normals take out a noise these frames lack): at the 95th
    # percentile a third of one hit's noise along the normal at grazing (0.9 cm at 50 m).
    q50, q95 = np.quantile(np.abs(r), [0.5, 0.95])
    assert q50 < 5e-4 and q95 < 3e-3
    # The sight meets those planes at grazing incidence (a group's mean lies among its hits'
    # sights, each within the limit).
    n = mapping.rotate(surf.normal_obs[groups.target], surf.line[groups.target])
    at_T = mapping.apply(groups.xyz_obs, groups.line)
    sight = mapping.apply(np.zeros_like(at_T), groups.line) - at_T
    cos = np.einsum("ni,ni->n", n, sight) / np.linalg.norm(sight, axis=1)
    assert np.all(cos > 0) and np.quantile(cos, 0.95) < MAX_COS_INCIDENCE


def test_the_groups_are_the_benchs_grazing_groups_as_pseudo_surfels(noisy: Case) -> None:
    data, mapping, surf, noise = noisy
    groups = find_grazing(data, mapping, surf, noise)
    bench, _ = match_hits(data, mapping, surf, noise, max_cos=MAX_COS_INCIDENCE)
    lin = linearize_hits(data, mapping, surf, noise, bench)
    # The bench's group of each (cell, target): the fit tries only the cells that look grazing,
    # whose groups hold the same hits as the bench's.
    target = np.zeros(len(bench.cell), dtype=np.int64)
    target[bench.group] = bench.target
    key = bench.cell * len(surf.planar) + target
    index = {k: i for i, k in enumerate(key)}
    same = np.array([index[k] for k in groups.cell * len(surf.planar) + groups.target])
    assert groups.groups > 100
    np.testing.assert_array_equal(groups.count, np.bincount(bench.group)[same])
    # Where they are found, a pseudo-surfel's residual is its hits' mean residual exactly.
    r, _, var = grazing_rows(groups, surf, mapping, noise)
    np.testing.assert_allclose(r, lin.r[same], rtol=0, atol=1e-12)
    np.testing.assert_allclose(var, lin.var[same], rtol=0.05)


def test_the_groups_jacobian_is_their_residuals_derivative_with_the_targets_normals_held(noise_free: Case) -> None:
    data, mapping, surf, noise = noise_free
    groups = find_grazing(data, mapping, surf, noise)
    r, J, _ = grazing_rows(groups, surf, mapping, noise)
    assert J is not None
    t = groups.target
    n0 = mapping.rotate(surf.normal_obs[t], surf.line[t])

    def residuals(x: np.ndarray) -> np.ndarray:
        moved = LineMapping(x, data.tau_s, mapping.free)
        d = moved.apply(groups.xyz_obs, groups.line) - moved.apply(surf.anchor_obs[t], surf.line[t])
        return np.asarray(np.einsum("ni,ni->n", n0, d))

    np.testing.assert_allclose(residuals(mapping.x), r, atol=1e-12)
    h = 1e-6
    for j in range(9):
        dx = np.zeros(9)
        dx[j] = h
        derivative = (residuals(mapping.x + dx) - residuals(mapping.x - dx)) / (2 * h)
        np.testing.assert_allclose(derivative, J[:, j], rtol=1e-5, atol=1e-6)


def test_hits_left_to_the_members_or_without_a_planar_surfel_give_no_groups(noise_free: Case) -> None:
    data, mapping, surf, noise = noise_free
    every = find_grazing(data, mapping, surf, noise)
    # Half of the grouped hits excluded (a member's): none of those in any group, the others as before.
    some = every.hit[::2]
    groups = find_grazing(data, mapping, surf, noise, exclude=some)
    assert groups.hits > 0 and not np.any(np.isin(groups.hit, some))
    np.testing.assert_array_equal(groups.hit, np.setdiff1d(every.hit, some))
    # No planar surfel in any frame, or in only one: nothing to match against in another frame.
    flat = np.zeros_like(surf.planar)
    assert find_grazing(data, mapping, _with_planar(surf, flat), noise).groups == 0
    flat[np.flatnonzero(surf.planar & (data.cell_frame == 0))] = True
    one_frame = find_grazing(data, mapping, _with_planar(surf, flat), noise)
    assert one_frame.groups > 0 and np.all(data.cell_frame[one_frame.target] == 0)
    assert Grazing.none().groups == 0 and Grazing.none().hits == 0


def _with_planar(surf: Surfels, planar: np.ndarray) -> Surfels:
    return replace(surf, planar=planar)


def test_the_terms_rows_are_in_one_order_and_the_groups_at_the_pairs_scale(noisy: Case) -> None:
    data, mapping, surf, noise = noisy
    cells = np.arange(len(data.cell_frame), dtype=np.int64)
    src, partner = partners(data, cells, np.random.default_rng(0), window=None, k=data.n_frames - 1)
    pairs = Terms(surf, match(data, mapping, surf, src, partner, 1.5 * data.surfel_m), Beams.none())
    terms = pairs.with_grazing(data, noise, mapping)
    n_pairs, n_groups = len(pairs.matches.src), terms.grazing.groups
    assert n_groups > 100
    lin = terms.linearize(data, noise, mapping)
    assert len(lin.r) == len(lin.var) == len(lin.J) == n_pairs + n_groups
    np.testing.assert_array_equal(terms.residuals(data, noise, mapping), lin.r)
    np.testing.assert_array_equal(lin.r[:n_pairs], pairs.linearize(data, noise, mapping).r)
    where = terms.positions(data, mapping)
    assert len(where) == len(lin.r)
    np.testing.assert_allclose(where[n_pairs:], mapping.apply(terms.grazing.xyz_obs, terms.grazing.line))
    # Each kind's residuals over their sigmas have one robust scale.
    e = lin.r / np.sqrt(lin.var)
    assert robust_sigma(e[n_pairs:]) == pytest.approx(robust_sigma(e[:n_pairs]), rel=1e-9)
