"""Feature tracks: the same target feature observed once per frame, validated once here.

A track observation is ``(track id, time t_s, position xyz_m)`` in the sensor frame, with
an optional frame index. When frames are not given they are inferred from the times: the
frame period is the typical interval between a track's successive observations, and frame
boundaries fall in the largest gap of the times modulo that period (the line-scan's idle
time between frames).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..errors import MalformedInputError, NonFiniteValueError, TimeOrderError
from .errors import DuplicateObservationError, SingleObservationTrackError, TooFewFramesError, TooFewTracksError
from .sensor import SensorNoise

MIN_FRAMES = 4
MIN_TRACKS = 3


@dataclass(frozen=True)
class Tracks:
    """Validated observations sorted by (frame, time).

    track_ids: names of the tracks; track: ``(n,)`` index into ``track_ids``;
    t_s: ``(n,)`` seconds; xyz_m: ``(n, 3)`` metres in the sensor frame;
    frame: ``(n,)`` frame index starting at 0; sensor: declared noise, if any.
    """

    track_ids: tuple[str, ...]
    track: NDArray[np.int64]
    t_s: NDArray[np.float64]
    xyz_m: NDArray[np.float64]
    frame: NDArray[np.int64]
    sensor: SensorNoise | None = None

    @property
    def n_frames(self) -> int:
        return int(self.frame.max()) + 1

    @property
    def n_tracks(self) -> int:
        return len(self.track_ids)

    def __len__(self) -> int:
        return len(self.t_s)

    @classmethod
    def from_arrays(
        cls,
        track: list[str] | NDArray[np.str_],
        t_s: NDArray[np.float64] | list[float],
        xyz_m: NDArray[np.float64] | list[list[float]],
        *,
        frame: NDArray[np.int64] | list[int] | None = None,
        sensor: SensorNoise | None = None,
    ) -> Tracks:
        """Validate raw observations; every problem raises an :class:`InputError` subclass."""
        names = np.asarray(track, dtype=str)
        t = np.asarray(t_s, dtype=float)
        xyz = np.asarray(xyz_m, dtype=float)
        n = len(names)
        if t.shape != (n,) or xyz.shape != (n, 3):
            raise MalformedInputError(
                f"expected {n} times and {n}x3 positions, got shapes {t.shape} and {xyz.shape}",
                field="observations",
            )
        _check_finite(t, "t")
        _check_finite(xyz, "xyz")
        ids, index = np.unique(names, return_inverse=True)
        _check_duplicates(index, t, ids)
        counts = np.bincount(index, minlength=len(ids))
        if np.any(counts < 2):
            once = [str(ids[i]) for i in np.flatnonzero(counts < 2)]
            raise SingleObservationTrackError(
                f"track(s) seen only once: {_short_list(once)}; a track needs 2 or more observations",
                field="observations.track",
            )
        if len(ids) < MIN_TRACKS:
            raise TooFewTracksError(
                f"{len(ids)} track(s) given; at least {MIN_TRACKS} are needed", field="observations.track"
            )
        if frame is None:
            frames = infer_frames(index, t)
        else:
            frames = np.asarray(frame)
            if frames.shape != (n,) or not np.issubdtype(frames.dtype, np.integer) or frames.min() < 0:
                raise MalformedInputError("frame must be a non-negative integer per observation", field="frame")
            frames = _check_frames(index, t, frames.astype(np.int64), ids)
        n_frames = int(frames.max()) + 1
        if n_frames < MIN_FRAMES:
            raise TooFewFramesError(
                f"observations span {n_frames} frame(s); at least {MIN_FRAMES} are needed", field="observations.t"
            )
        order = np.lexsort((t, frames))
        return cls(
            track_ids=tuple(str(s) for s in ids),
            track=index[order].astype(np.int64),
            t_s=t[order],
            xyz_m=xyz[order],
            frame=frames[order],
            sensor=sensor,
        )

    def select(self, keep: NDArray[np.bool_]) -> Tracks:
        """The observations where ``keep`` is true (internal: no re-validation)."""
        used = np.unique(self.track[keep])
        remap = np.full(self.n_tracks, -1, dtype=np.int64)
        remap[used] = np.arange(len(used))
        return Tracks(
            track_ids=tuple(self.track_ids[i] for i in used),
            track=remap[self.track[keep]],
            t_s=self.t_s[keep],
            xyz_m=self.xyz_m[keep],
            frame=self.frame[keep],
            sensor=self.sensor,
        )

    def first_frames(self, count: int) -> Tracks:
        """The observations of frames ``0..count-1`` (tracks left with one observation dropped)."""
        keep = self.frame < count
        counts = np.bincount(self.track[keep], minlength=self.n_tracks)
        return self.select(keep & (counts[self.track] >= 2))

    def frame_times_s(self) -> NDArray[np.float64]:
        """Mean observation time of each frame, ``(n_frames,)``."""
        sums = np.bincount(self.frame, weights=self.t_s, minlength=self.n_frames)
        counts = np.bincount(self.frame, minlength=self.n_frames)
        return np.asarray(sums / np.maximum(counts, 1), dtype=float)


def infer_frames(track: NDArray[np.int64], t_s: NDArray[np.float64]) -> NDArray[np.int64]:
    """Frame index of each observation from the times alone (see the module docstring)."""
    order = np.lexsort((t_s, track))
    same = track[order][1:] == track[order][:-1]
    gaps = np.diff(t_s[order])[same]
    gaps = gaps[gaps > 0]
    period = float(np.median(gaps))
    # Refine with gaps that skip frames (a feature out of view) folded back to one period.
    period = float(np.median(gaps / np.maximum(np.round(gaps / period), 1.0)))
    t0 = float(t_s.min())
    phase = np.sort(np.mod(t_s - t0, period))
    circular = np.diff(np.concatenate([phase, [phase[0] + period]]))
    widest = int(np.argmax(circular))
    boundary = phase[widest] + circular[widest] / 2
    frames = np.floor((t_s - t0 - boundary) / period).astype(np.int64)
    return np.asarray(frames - frames.min(), dtype=np.int64)


def _check_finite(a: NDArray[np.float64], name: str) -> None:
    bad = ~np.isfinite(a)
    if bad.any():
        i = int(np.flatnonzero(bad.reshape(len(a), -1).any(axis=1))[0])
        raise NonFiniteValueError(
            f"observations[{i}].{name} is not a finite number (NaN or infinity)", field=f"observations[{i}].{name}"
        )


def _check_duplicates(index: NDArray[np.int64], t: NDArray[np.float64], ids: NDArray[np.str_]) -> None:
    order = np.lexsort((t, index))
    dup = (index[order][1:] == index[order][:-1]) & (t[order][1:] == t[order][:-1])
    if dup.any():
        i = order[int(np.flatnonzero(dup)[0])]
        raise DuplicateObservationError(
            f"track {ids[index[i]]!r} has two observations at t={t[i]!r} s", field="observations"
        )


def _check_frames(
    index: NDArray[np.int64], t: NDArray[np.float64], frames: NDArray[np.int64], ids: NDArray[np.str_]
) -> NDArray[np.int64]:
    key = index * (int(frames.max()) + 1) + frames
    uniq, counts = np.unique(key, return_counts=True)
    if np.any(counts > 1):
        k = int(uniq[np.argmax(counts > 1)])
        n_f = int(frames.max()) + 1
        raise DuplicateObservationError(
            f"track {ids[k // n_f]!r} is observed more than once in frame {k % n_f}", field="observations.frame"
        )
    present = np.unique(frames)
    lo = np.full(present.max() + 1, np.inf)
    hi = np.full(present.max() + 1, -np.inf)
    np.minimum.at(lo, frames, t)
    np.maximum.at(hi, frames, t)
    lo, hi = lo[present], hi[present]
    late = np.flatnonzero(hi[:-1] >= lo[1:])
    if late.size:
        f = int(late[0])
        raise TimeOrderError(
            f"times out of order: frame {present[f]} has an observation at t={hi[f]} s, "
            f"not before frame {present[f + 1]} starts at t={lo[f + 1]} s",
            field="observations.t",
        )
    # Frames without any observation are closed up so indices stay consecutive.
    return np.asarray(np.searchsorted(present, frames), dtype=np.int64)


def _short_list(items: list[str], limit: int = 5) -> str:
    shown = ", ".join(repr(s) for s in items[:limit])
    return shown + (f" and {len(items) - limit} more" if len(items) > limit else "")
