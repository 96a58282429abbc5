"""The report's frame strip shows the target, not the sky around it."""

from __future__ import annotations

import numpy as np

from tumblescan.spin_rate.report import _target_box


def test_the_strip_crops_to_the_target_in_every_frame() -> None:
    rng = np.random.default_rng(0)
    frames = []
    for x in (100, 140, 180):  # the target moves right across three frames
        g = rng.normal(10.0, 1.0, (512, 512))
        g[200:260, x : x + 60] = 200.0
        frames.append(g)
    x0, y0, x1, y1 = _target_box(frames)
    assert x0 <= 100 and x1 >= 240 and y0 <= 200 and y1 >= 260  # every frame's target inside
    assert x1 - x0 == y1 - y0 and x1 - x0 < 300  # a square, much smaller than the frame


def test_a_blank_sequence_keeps_the_whole_frame() -> None:
    frames = [np.full((64, 80), 5.0)]
    assert _target_box(frames) == (0, 0, 80, 64)
