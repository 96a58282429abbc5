"""The dense data of seeded frames at the true motion, as the estimator prepares them: shared by
the diagnostic benches that look at surfels and residuals at the truth."""

from __future__ import annotations

import numpy as np

from tumblescan import Motion, Scene, simulate_frames
from tumblescan.linescan.dense.data import DenseData, prepare
from tumblescan.linescan.dense.estimate import surfel_size_m
from tumblescan.linescan.dense.mapping import LineMapping
from tumblescan.linescan.dense.registration import extent_m
from tumblescan.linescan.simulate import FrameCloud


def frames_at_truth(motion: Motion, scene: Scene, noise_seed: int) -> tuple[FrameCloud, DenseData, LineMapping]:
    """Frames of ``motion`` (noise drawn with ``noise_seed``), their dense data (reference time
    ``T`` the first point's, surfel size the estimator's) and the true motion's line mapping
    (``mapping.x``: the truth at ``T``, all 9 parameters free)."""
    sim = simulate_frames(motion, scene, seed=noise_seed)
    T = float(sim.t_s.min())
    data = dense_data(sim, T, scene.scanner.noise.range_sigma_m)
    return sim, data, LineMapping(motion.at_reference(T).params(), data.tau_s, tuple(range(9)))


def dense_data(sim: FrameCloud, reference_time_s: float, range_sigma_m: float) -> DenseData:
    """The dense data of the frames ``sim`` as the estimator prepares them: times from
    ``reference_time_s`` (s), cells of its size (``surfel_size_m`` of the largest frame's extent)
    for range noise ``range_sigma_m`` (m)."""
    frame = sim.frame.astype(np.int64)
    per_frame = [sim.xyz_m[frame == f] for f in range(int(frame.max()) + 1)]
    surfel_m = surfel_size_m(extent_m(per_frame), range_sigma_m)
    return prepare(sim.xyz_m, sim.t_s - reference_time_s, frame, surfel_m=surfel_m, range_sigma_m=range_sigma_m)
