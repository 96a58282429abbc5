"""From frames to line observations: target masks, segments, tracks (steps 1-3 of the recipe)."""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray, Progress
from ..numerics.parallel import parallel_map
from .errors import NoTargetError
from .segments import Segments, frame_segments
from .target import TargetMask, find_target, to_gray8
from .tracking import Track, build_tracks, match, predict_affine


@dataclass
class Features:
    targets: list[TargetMask]
    segments: list[Segments]
    tracks: list[Track]
    rotation_deg: dict[tuple[int, int], float]
    affines: dict[tuple[int, int], FloatArray]


def extract(grays: list[FloatArray], full_scale: float, polarity: str, progress: Progress) -> Features:
    """Masks, LSD segments and tracks of every frame; ``NoTargetError`` when the target is found in
    fewer than half the frames."""
    targets = [find_target(g, full_scale, polarity) for g in grays]
    found = [k for k, t in enumerate(targets) if t.found]
    if len(found) < max(len(grays) / 2, 2):
        raise NoTargetError(
            f"frames: the target was found in {len(found)} of {len(grays)} frames "
            f"(a blob of at least 150 px above the sky in at least half of them is needed)",
            field="frames",
        )
    # Each frame's segments, and each pair's image-to-image prediction, on their own.
    segments = parallel_map(
        _segments_of, [(g, to_gray8(g, t, full_scale, polarity), t) for g, t in zip(grays, targets, strict=True)]
    )
    progress("lines", 0.4)
    steps = list(itertools.pairwise(found))
    predicted = parallel_map(_affine_of, [(grays[k], grays[l_], targets[k], targets[l_]) for k, l_ in steps])
    progress("tracking", 0.5)
    pairs: dict[tuple[int, int], list[tuple[int, int]]] = {}
    rotation: dict[tuple[int, int], float] = {}
    affines: dict[tuple[int, int], FloatArray] = {}
    for (k, l_), A in zip(steps, predicted, strict=True):
        pairs[(k, l_)] = match(segments[k].ends_px, segments[l_].ends_px, A)
        affines[(k, l_)] = A
        rotation[(k, l_)] = float(np.degrees(np.arctan2(A[1, 0] - A[0, 1], A[0, 0] + A[1, 1])))
    progress("tracking", 0.6)
    return Features(targets, segments, build_tracks(segments, pairs), rotation, affines)


def _segments_of(frame: tuple[FloatArray, np.ndarray, TargetMask]) -> Segments:
    return frame_segments(*frame)


def _affine_of(pair: tuple[FloatArray, FloatArray, TargetMask, TargetMask]) -> FloatArray:
    return predict_affine(*pair)[0]
