"""The sight-match bench (``bench/linescan/sight_match.py``): a hit's target where its line of
sight meets a plane does not move with the hit's range noise, and its designs' groups."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
import pytest
from bench.linescan.reuse_diag import at_truth
from bench.linescan.sight_match import FAR, SightReach, against_mesh, design_groups, match_by_sight, mesh_truth

from tumblescan import Motion, Scanner, Scene
from tumblescan.linescan.dense.beams import Beams
from tumblescan.linescan.dense.data import DenseData
from tumblescan.linescan.dense.grazing import at_reference, match_to_surfels
from tumblescan.linescan.dense.mapping import LineMapping
from tumblescan.linescan.dense.surfels import Surfels
from tumblescan.linescan.sensor import SensorNoise
from tumblescan.linescan.simulate import FrameCloud

from ..conftest import motion_for

Case = tuple[DenseData, LineMapping, Surfels, SensorNoise]
Matcher = Callable[[DenseData, LineMapping, Surfels, SensorNoise, np.ndarray], tuple[np.ndarray, np.ndarray]]


@pytest.fixture(scope="module")
def box_truth() -> tuple[Scene, Motion, FrameCloud, DenseData, LineMapping, Surfels]:
    scene = Scene(scanner=Scanner(lines=160, pixels=160), noise=False)
    motion = motion_for(1, distance_m=50.0)
    return (scene, motion, *at_truth(motion, scene, 1))


@pytest.fixture(scope="module")
def noise_free(box_truth: tuple[Scene, Motion, FrameCloud, DenseData, LineMapping, Surfels]) -> Case:
    scene, _, _, data, mapping, surf = box_truth
    return data, mapping, surf, scene.scanner.noise


def test_a_hit_moved_along_its_sight_keeps_its_target_by_sight_not_by_nearest_anchor(noise_free: Case) -> None:
    data, mapping, surf, noise = noise_free
    hits = np.flatnonzero(~surf.planar[surf.point_cell])
    rho = np.linalg.norm(data.xyz_m, axis=1)
    # Range noise moves a hit along its line of sight: 2 cm either way.
    step_m = np.random.default_rng(3).choice([-0.02, 0.02], len(rho))
    moved = replace(data, xyz_m=data.xyz_m * (1 + step_m / rho)[:, None])

    def kept_share(match: Matcher) -> float:
        pairs = [match(d, mapping, surf, noise, hits) for d in (data, moved)]
        keys = [hit * data.n_frames + data.cell_frame[target] for hit, target in pairs]
        both, i, j = np.intersect1d(keys[0], keys[1], return_indices=True)
        assert len(both) > 0.8 * min(len(keys[0]), len(keys[1])) > 1000
        return float(np.mean(pairs[0][1][i] == pairs[1][1][j]))

    by_sight = kept_share(match_by_sight)
    by_anchor = kept_share(lambda *a: match_to_surfels(*a, max_cos=None))
    # (4.3 % of the nearest anchor's matches change targets, 0.05 % of the sight's.)
    assert by_sight > 0.995 and by_anchor < 0.98


def test_the_designs_groups_hold_their_matches(noise_free: Case) -> None:
    data, mapping, surf, noise = noise_free
    designs, seconds = design_groups(data, mapping, surf, noise, Beams.none())
    assert designs["pairs"][0].groups == 0 and set(seconds) <= set(designs)
    for label in ("grazing", "sight", "grazing + steep sight"):
        groups, hit, target = designs[label]
        assert groups.groups > 100 and groups.hits == len(np.unique(hit))
        assert np.all(surf.planar[target]) and not np.any(surf.planar[surf.point_cell[hit]])
    # The combined design: the fit's own matches first, then sight matches in frames they left.
    g_hit = designs["grazing"][1]
    both_hit, both_target = designs["grazing + steep sight"][1:]
    np.testing.assert_array_equal(both_hit[: len(g_hit)], g_hit)
    keys = both_hit * data.n_frames + data.cell_frame[both_target]
    assert len(np.unique(keys)) == len(keys) > len(g_hit)
    # The sight design takes left-out hits at every incidence, more than the grazing ones.
    assert designs["sight"][0].hits > designs["grazing"][0].hits
    # The grazing cells' design: the fit's matches first, then candidates' matches to cells that
    # hold candidates themselves (none planar).
    cells_hit, cells_target = designs["grazing + grazing cells"][1:]
    np.testing.assert_array_equal(cells_hit[: len(g_hit)], g_hit)
    extra = cells_target[len(g_hit) :]
    assert len(extra) > 0 and not np.any(surf.planar[extra])


def test_the_prefilter_keeps_the_sight_matches_at_steep_incidence(noise_free: Case) -> None:
    data, mapping, surf, noise = noise_free
    hits = np.flatnonzero(~surf.planar[surf.point_cell])
    hit, target = match_by_sight(data, mapping, surf, noise, hits, min_cos=0.3)
    every_hit, every_target = match_by_sight(data, mapping, surf, noise, hits)
    x_ref, sensor_ref, _, normal_ref = at_reference(data, mapping, surf, every_hit)
    u = sensor_ref - x_ref
    steep = np.einsum("ni,ni->n", normal_ref[every_target], u) >= 0.3 * np.linalg.norm(u, axis=1)
    kept = set(zip(hit.tolist(), target.tolist(), strict=True))
    wanted = set(zip(every_hit[steep].tolist(), every_target[steep].tolist(), strict=True))
    assert kept <= wanted and len(kept) > 0.99 * len(wanted) > 1000


def test_the_far_sight_finds_the_faces_margins_and_keeps_the_next_face_out(
    box_truth: tuple[Scene, Motion, FrameCloud, DenseData, LineMapping, Surfels],
) -> None:
    scene, motion, sim, data, mapping, surf = box_truth
    noise = scene.scanner.noise
    hits = np.flatnonzero(~surf.planar[surf.point_cell])
    face, surf_face, planes = mesh_truth(scene, motion, sim, data, mapping, surf)

    def on_face(reach: SightReach) -> tuple[int, float]:
        hit, target = match_by_sight(data, mapping, surf, noise, hits, min_cos=0.3, reach=reach)
        return len(hit), against_mesh(hit, target, face, surf_face, data, mapping, noise, planes)[0]

    near, _ = on_face(SightReach())
    far, far_share = on_face(FAR)
    any_cell, any_share = on_face(replace(FAR, agree_deg=180.0))
    # Farther out the sight finds more; the hit's own cell's direction keeps it on the face
    # (99.8 % of its matches on their target's face; without that test 98.3 %).
    assert far > 1.5 * near and far_share > 0.97
    assert any_cell > far and any_share < far_share - 0.01
