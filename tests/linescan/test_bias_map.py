"""The bias-map bench's surfel variants (``bench/linescan/bias_map.py``): the anchors with their
points' noise taken out."""

from __future__ import annotations

import numpy as np
import pytest
from bench.linescan.bias_map import anchor_noise_m, variant_surfels
from bench.linescan.dense_bound import last_stage_matches
from bench.linescan.draw_bias import measured_scale
from bench.linescan.loss_choice import normalised

from tumblescan import Scanner, Scene
from tumblescan.linescan.dense.data import DenseData
from tumblescan.linescan.dense.mapping import LineMapping
from tumblescan.linescan.dense.matching import linearize
from tumblescan.linescan.dense.surfels import Surfels
from tumblescan.linescan.simulate import FrameCloud

from ..conftest import motion_for


def _offsets_from_true_planes(
    anchors_obs: np.ndarray, sim: FrameCloud, data: DenseData, mapping: LineMapping, surf: Surfels, cells: np.ndarray
) -> np.ndarray:
    """Each surfel's anchor (mapped to ``T`` at the true motion) off the plane of its points'
    noise-free hits at ``T`` (m), for ``cells``."""
    kept = slice(None) if data.kept is None else data.kept
    true_T = mapping.apply(sim.xyz_true_m[kept], data.line)
    anchors_T = mapping.apply(anchors_obs[cells], surf.line[cells])
    out = np.empty(len(cells))
    for i, c in enumerate(cells):
        p = true_T[surf.point_cell == c]
        centre = p.mean(axis=0)
        normal = np.linalg.eigh(np.cov((p - centre).T))[1][:, 0]
        out[i] = (anchors_T[i] - centre) @ normal
    return out


def test_noise_free_anchors_lie_on_the_surface_and_the_noise_is_the_model_s() -> None:
    motion = motion_for(1, distance_m=50.0)
    scene = Scene(scanner=Scanner(lines=160, pixels=160))
    sim, data, mapping, surf = variant_surfels("none", motion, scene, 1)
    clean = variant_surfels("noise-free-anchors", motion, scene, 1)[3]
    planar = np.flatnonzero(surf.planar)
    assert len(planar) > 300
    # What the variant takes out is the anchors' noise, of the size the surfels' model gives it
    # along the normal (the sensor's variance over the point count): the covariance relies on it.
    noise = anchor_noise_m(sim, data, surf)
    sd_m = np.sqrt(surf.var_m2[planar] / surf.count[planar])
    z = np.einsum("ni,ni->n", noise[planar], surf.normal_obs[planar]) / sd_m
    assert 0.85 < np.sqrt(np.mean(z**2)) < 1.15
    assert abs(np.mean(z)) < 0.15
    # On the box's flat faces the anchors without it lie on their points' true plane; the
    # measured ones lie off it by their noise.
    sample = planar[:: max(1, len(planar) // 300)]
    sd_sample = np.sqrt(surf.var_m2[sample] / surf.count[sample])
    off_clean = _offsets_from_true_planes(clean.anchor_obs, sim, data, mapping, surf, sample) / sd_sample
    off_noisy = _offsets_from_true_planes(surf.anchor_obs, sim, data, mapping, surf, sample) / sd_sample
    assert np.median(np.abs(off_clean)) < 0.05
    assert 0.4 < np.median(np.abs(off_noisy)) < 1.0


def test_the_clean_anchors_pairs_are_weighed_at_the_measured_scale() -> None:
    motion = motion_for(1, distance_m=50.0)
    scene = Scene(scanner=Scanner(lines=160, pixels=160))
    noise = scene.scanner.noise
    sim, data, mapping, clean = variant_surfels("noise-free-anchors", motion, scene, 1)
    measured = variant_surfels("none", motion, scene, 1)[3]
    matches, lin_clean = last_stage_matches(data, mapping, clean, noise)
    # The measured anchors' residuals are about as large as the noise model says; the clean
    # anchors' are the surfels' misfit alone, far smaller, and are weighed at the former's scale.
    s_measured = normalised(linearize(data, mapping, measured, matches, noise))[1]
    assert 0.85 < s_measured < 1.3
    assert normalised(lin_clean)[1] < 0.3 * s_measured
    assert measured_scale(sim, data, mapping, clean, matches, noise) == pytest.approx(s_measured, rel=1e-9)
