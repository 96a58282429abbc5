"""Each surfel's misfit (:mod:`tumblescan.linescan.dense.misfit`): at the true motion, surfels whose
anchors were moved off the surface are singled out, by about the distance they were moved, and
the others are left as the noise model has them."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from bench.linescan.dense_bound import last_stage_matches
from bench.linescan.truth import frames_at_truth

from tumblescan import Scanner, Scene, random_motion
from tumblescan.linescan.dense.matching import robust_sigma
from tumblescan.linescan.dense.misfit import surfel_misfit
from tumblescan.linescan.dense.surfels import build_surfels
from tumblescan.target.shape import SatelliteShape

MOVED_M = 0.004


@pytest.fixture(scope="module")
def box_at_truth() -> tuple:
    motion = random_motion(np.random.default_rng(0), distance_m=50.0)
    scene = Scene(scanner=Scanner(lines=512, pixels=512), shape=SatelliteShape())
    _, data, mapping = frames_at_truth(motion, scene, 0)
    return data, mapping, build_surfels(data, mapping, scene.scanner.noise), scene.scanner.noise


def _misfit(data, mapping, surf, noise) -> tuple[np.ndarray, np.ndarray, float]:  # type: ignore[no-untyped-def]
    """The misfit of every surfel, which surfels have residuals, and the residuals' scale."""
    matches, lin = last_stage_matches(data, mapping, surf, noise)
    seen = np.zeros(len(surf.line), dtype=bool)
    seen[matches.src] = seen[matches.dst] = True
    scale = robust_sigma(lin.r[: len(matches.src)] / np.sqrt(lin.var[: len(matches.src)]))
    return surfel_misfit(surf, matches, lin), seen, scale


def test_a_box_at_the_truth_has_almost_no_misfit(box_at_truth: tuple) -> None:
    data, mapping, surf, noise = box_at_truth
    tau2, seen, _ = _misfit(data, mapping, surf, noise)
    own = surf.var_m2 / np.maximum(surf.count, 1)
    ratio = tau2[seen] / own[seen]
    # Under the noise model delta^2 / v is about chi-square with one degree: its excess over 1
    # is zero for about two surfels in three, and above 9 (three sigmas) for about one in 400.
    assert np.mean(ratio == 0) > 0.6, np.mean(ratio == 0)
    assert np.mean(ratio > 9) < 0.01, np.mean(ratio > 9)


def test_surfels_moved_off_the_surface_are_singled_out(box_at_truth: tuple) -> None:
    data, mapping, surf, noise = box_at_truth
    rng = np.random.default_rng(1)
    moved = rng.choice(np.flatnonzero(surf.planar), 30, replace=False)
    anchor = surf.anchor_obs.copy()
    anchor[moved] += MOVED_M * surf.normal_obs[moved]
    tau2, seen, scale = _misfit(data, mapping, replace(surf, anchor_obs=anchor), noise)
    assert np.all(seen[moved])
    # The misfit's square root, back in metres, is about the distance moved.
    moved_by_m = scale * np.sqrt(tau2[moved])
    assert np.median(moved_by_m) == pytest.approx(MOVED_M, rel=0.2), moved_by_m
    assert np.mean(moved_by_m > MOVED_M / 2) >= 0.8, moved_by_m
    # The others' is of the order of their noise (their partners' means moved by a few in 14).
    others = seen & ~np.isin(np.arange(len(tau2)), moved)
    assert np.mean(tau2[others] == 0) > 0.6
