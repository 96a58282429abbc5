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
from .tracking import (
    Prediction,
    Track,
    better_prediction,
    build_tracks,
    match,
    predict_affine,
    retry_grid,
    suspect_turns,
    untrusted_pairs,
)


@dataclass
class Features:
    targets: list[TargetMask]
    segments: list[Segments]
    tracks: list[Track]
    rotation_deg: dict[tuple[int, int], float]
    affines: dict[tuple[int, int], FloatArray]


def extract(
    grays: list[FloatArray], full_scale: float, polarity: str, progress: Progress, t_s: FloatArray | None = None
) -> Features:
    """Masks, LSD segments and tracks of every frame (times ``t_s`` (F,) s, default the frame
    index); ``NoTargetError`` when the target is found in fewer than half the frames."""
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
    times = np.arange(len(grays), dtype=float) if t_s is None else t_s
    predicted = _consistent(grays, targets, steps, predicted, times)
    untrusted = _untrusted(steps, predicted, times)
    progress("tracking", 0.5)
    pairs: dict[tuple[int, int], list[tuple[int, int]]] = {}
    rotation: dict[tuple[int, int], float] = {}
    affines: dict[tuple[int, int], FloatArray] = {}
    for (k, l_), pred, off in zip(steps, predicted, untrusted, strict=True):
        pairs[(k, l_)] = [] if off else match(segments[k].ends_px, segments[l_].ends_px, pred.affine)
        affines[(k, l_)] = pred.affine
        rotation[(k, l_)] = pred.turn_deg
    progress("tracking", 0.6)
    return Features(targets, segments, build_tracks(segments, pairs), rotation, affines)


def _turns(
    steps: list[tuple[int, int]], predicted: list[Prediction], t_s: FloatArray
) -> tuple[FloatArray, FloatArray, np.ndarray]:
    """Each pair's turn (deg), interval (s) and whether its ECC converged."""
    turns = np.array([p.turn_deg for p in predicted])
    dt = np.array([t_s[l_] - t_s[k] for k, l_ in steps], dtype=float)
    return turns, dt, np.isfinite([p.ecc_rho for p in predicted])


def _untrusted(steps: list[tuple[int, int]], predicted: list[Prediction], t_s: FloatArray) -> np.ndarray:
    """(P,) bool: the pairs not to match across (``tracking.untrusted_pairs``)."""
    if not steps:
        return np.zeros(0, dtype=bool)
    return untrusted_pairs(*_turns(steps, predicted, t_s))


def _segments_of(frame: tuple[FloatArray, np.ndarray, TargetMask]) -> Segments:
    return frame_segments(*frame)


def _affine_of(pair: tuple[FloatArray, FloatArray, TargetMask, TargetMask]) -> Prediction:
    return predict_affine(*pair)


def _retry_of(pair: tuple[FloatArray, FloatArray, TargetMask, TargetMask, float]) -> Prediction:
    prev, next_, tp, tn, expected = pair
    return predict_affine(prev, next_, tp, tn, angles_deg=retry_grid(expected))


def _consistent(
    grays: list[FloatArray], targets: list[TargetMask], steps: list[tuple[int, int]], predicted: list[Prediction],
    t_s: FloatArray,
) -> list[Prediction]:  # fmt: skip
    """``predicted`` with each suspect pair (``tracking.suspect_turns``: its turn far from the median
    rate's, or its ECC not converged) predicted again about the expected turn, the better kept."""
    if not steps:
        return predicted
    turns, dt, converged = _turns(steps, predicted, t_s)
    expected = suspect_turns(turns, dt, converged)
    redo = np.flatnonzero(np.isfinite(expected))
    retried = parallel_map(
        _retry_of,
        [(grays[k], grays[l_], targets[k], targets[l_], float(expected[i])) for i in redo for k, l_ in [steps[i]]],
    )
    out = list(predicted)
    for i, r in zip(redo, retried, strict=True):
        out[i] = better_prediction(predicted[i], r)
    return out
