"""Frame assembly for dense line-scan data: a timed cloud split into frames and lines, and
range images (NPZ) turned into such a cloud with the scanner geometry.

A frame needs at least two distinct line times (a line-scan frame is not a snapshot), and an
estimate needs at least ``MIN_FRAMES`` frames. Frames come from a per-point ``frame`` field
when present, otherwise from the scanner's frame period, otherwise from the idle gaps between
frames in the times; lines come from a ``line`` field or from the distinct times in a frame.

Point NPZ: ``xyz_m`` (n, 3), ``t_s`` (n,), optional integer ``frame`` and ``line``.
Range-image NPZ: ``range_m`` (frames, lines, pixels; 0 where the ray had no return),
``t_s`` (frames, lines), ``azimuth_deg`` (lines,) or (frames, lines), ``elevation_deg``
(pixels,). The archive is inspected before anything is decompressed: only these names, no
pickles, and declared sizes within ``max_bytes`` (so a zip bomb is refused unread).
"""

from __future__ import annotations

import os
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..errors import LimitExceededError, MalformedInputError, NonFiniteValueError, TimeOrderError
from ..io.ply import TimedCloud, check_line_times, read_ply
from .errors import TooFewFramesError
from .sensor import directions
from .tracks import MIN_FRAMES

# Consecutive distinct times further apart than this many typical line intervals start a new frame.
FRAME_GAP_FACTOR = 10.0
NPZ_KEYS = ("range_m", "t_s", "azimuth_deg", "elevation_deg")
POINT_KEYS = ("xyz_m", "t_s")


@dataclass(frozen=True)
class Frames:
    """A cloud with the frame (0..n-1) and line (within its frame) of every point."""

    cloud: TimedCloud
    frame: NDArray[np.int64]
    line: NDArray[np.int64]

    @property
    def n_frames(self) -> int:
        return int(self.frame.max()) + 1

    def frame_times_s(self) -> NDArray[np.float64]:
        """Mean point time of each frame."""
        counts = np.bincount(self.frame, minlength=self.n_frames)
        return np.asarray(np.bincount(self.frame, weights=self.cloud.t_s, minlength=self.n_frames) / counts)


def assemble_frames(cloud: TimedCloud, *, frame_period_s: float | None = None) -> Frames:
    """Split ``cloud`` into frames and lines (see the module docstring); every problem raises an
    :class:`~tumblescan.errors.InputError` naming it."""
    if len(cloud) == 0:
        raise MalformedInputError("the cloud has no points", field="file")
    frame = _frames(cloud, frame_period_s)
    # Close up frame numbers so they run 0..n-1.
    frame = np.unique(frame, return_inverse=True)[1].astype(np.int64)
    n_frames = int(frame.max()) + 1
    if n_frames < MIN_FRAMES:
        raise TooFewFramesError(f"the cloud spans {n_frames} frame(s); at least {MIN_FRAMES} are needed", field="file")
    t = cloud.t_s
    lo = np.full(n_frames, np.inf)
    hi = np.full(n_frames, -np.inf)
    np.minimum.at(lo, frame, t)
    np.maximum.at(hi, frame, t)
    flat = np.flatnonzero(hi <= lo)
    if flat.size:
        raise TimeOrderError(
            f"times do not vary within frame {int(flat[0])} (all t={lo[flat[0]]} s): a line-scan frame needs a time "
            "per line; were the points given the frame's time instead?",
            field="t",
        )
    return Frames(cloud=cloud, frame=frame, line=_lines(cloud, frame))


def _frames(cloud: TimedCloud, frame_period_s: float | None) -> NDArray[np.int64]:
    if "frame" in cloud.fields:
        if frame_period_s is not None:
            # Given both, one would be ignored: the user who gave the period expects it used.
            raise MalformedInputError(
                "the points carry a 'frame' property, which sets the frames: a frame period applies only without it",
                field="frame_period_s",
            )
        f = np.asarray(cloud.fields["frame"])
        if not np.issubdtype(f.dtype, np.integer) or (f < 0).any():
            raise MalformedInputError("the 'frame' property must hold non-negative integers", field="frame")
        return f.astype(np.int64)
    t = cloud.t_s
    if frame_period_s is not None:
        if not frame_period_s > 0:
            raise MalformedInputError("frame_period_s must be positive", field="frame_period_s")
        return np.floor((t - t.min()) / frame_period_s + 1e-9).astype(np.int64)
    # The idle time between frames shows as gaps far longer than a line interval.
    times = np.unique(t)
    if len(times) < 2:
        raise TimeOrderError("all points have the same time: a line-scan cloud needs a time per line", field="t")
    steps = np.diff(times)
    gap = steps > FRAME_GAP_FACTOR * np.median(steps)
    if not gap.any():
        raise MalformedInputError(
            "cannot tell the frames apart: the times show no gaps between frames; give a 'frame' property per point "
            "or the scanner's frame period",
            field="frame",
        )
    starts = np.concatenate([[times[0]], times[1:][gap]])
    return (np.searchsorted(starts, t, side="right") - 1).astype(np.int64)


def _lines(cloud: TimedCloud, frame: NDArray[np.int64]) -> NDArray[np.int64]:
    if "line" in cloud.fields:
        return np.asarray(cloud.fields["line"]).astype(np.int64)
    # Without indices, a line is a distinct time within a frame, numbered from 0 in time order.
    order = np.lexsort((cloud.t_s, frame))
    f, t = frame[order], cloud.t_s[order]
    new_frame = np.ones(len(order), bool)
    new_frame[1:] = f[1:] != f[:-1]
    new_line = new_frame.copy()
    new_line[1:] |= t[1:] != t[:-1]
    counter = np.cumsum(new_line) - 1
    frame_start = np.maximum.accumulate(np.where(new_frame, counter, 0))
    line = np.empty(len(order), dtype=np.int64)
    line[order] = counter - frame_start
    return line


def read_frames(
    path: str | os.PathLike[str], *, frame_period_s: float | None = None, max_bytes: int = 2 << 30
) -> Frames:
    """Frames from a PLY with per-point times, an NPZ of points (``xyz_m`` ``(n, 3)``, ``t_s``,
    optional integer ``frame`` and ``line``) or an NPZ of range images (module docstring)."""
    p = Path(path)
    with open(p, "rb") as fh:
        head = fh.read(4)
    if head.startswith(b"ply"):
        return assemble_frames(read_ply(p), frame_period_s=frame_period_s)
    if not head.startswith(b"PK"):
        raise MalformedInputError("a frames file must be a PLY or an NPZ", field="file")
    names = _npz_names(p)
    cloud = read_range_images(p, max_bytes=max_bytes) if "range_m" in names else _read_point_npz(p, max_bytes)
    return assemble_frames(cloud, frame_period_s=frame_period_s)


def _read_point_npz(path: Path, max_bytes: int) -> TimedCloud:
    arrays = _load_npz(path, max_bytes, required=POINT_KEYS, optional=("frame", "line"))
    xyz, t = arrays["xyz_m"], arrays["t_s"]
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise MalformedInputError(f"xyz_m must be (n, 3); got shape {xyz.shape}", field="xyz_m")
    if t.shape != (len(xyz),):
        raise MalformedInputError(f"t_s must be ({len(xyz)},), one time per point; got {t.shape}", field="t_s")
    for name, a in (("xyz_m", xyz), ("t_s", t)):
        if not np.isfinite(a).all():
            raise NonFiniteValueError(f"{name} holds NaN or infinity", field=name)
    fields: dict[str, np.ndarray] = {}
    for name in ("frame", "line"):
        if name in arrays:
            a = arrays[name]
            if a.shape != (len(xyz),) or not np.all(a == np.round(a)) or (a < 0).any():
                raise MalformedInputError(f"{name} must hold one non-negative integer per point", field=name)
            fields[name] = a.astype(np.int32)
    cloud = TimedCloud(xyz_m=xyz, t_s=t, fields=fields)
    check_line_times(cloud)
    return cloud


def read_range_images(path: str | os.PathLike[str], *, max_bytes: int = 2 << 30) -> TimedCloud:
    """Points (with ``frame``, ``line`` and ``pixel``) from a range-image NPZ (module docstring)."""
    p = Path(path)
    arrays = _load_npz(p, max_bytes, required=NPZ_KEYS, optional=())
    rng_m, t, az, el = (arrays[k] for k in NPZ_KEYS)
    if rng_m.ndim != 3:
        raise MalformedInputError(f"range_m must be (frames, lines, pixels); got shape {rng_m.shape}", field="range_m")
    n_f, n_l, n_p = rng_m.shape
    if t.shape != (n_f, n_l):
        raise MalformedInputError(f"t_s must be (frames, lines) = {(n_f, n_l)}; got {t.shape}", field="t_s")
    if az.shape not in ((n_l,), (n_f, n_l)):
        raise MalformedInputError(
            f"azimuth_deg must be (lines,) or (frames, lines); got {az.shape}", field="azimuth_deg"
        )
    if el.shape != (n_p,):
        raise MalformedInputError(f"elevation_deg must be (pixels,) = ({n_p},); got {el.shape}", field="elevation_deg")
    for name, a in (("range_m", rng_m), ("t_s", t), ("azimuth_deg", az), ("elevation_deg", el)):
        if not np.isfinite(a).all():
            raise NonFiniteValueError(f"{name} holds NaN or infinity (use range 0 for no return)", field=name)
    if (rng_m < 0).any():
        raise MalformedInputError("range_m must not be negative (0 marks no return)", field="range_m")
    f_i, k_i, p_i = np.nonzero(rng_m > 0)
    az_rad = np.radians(np.broadcast_to(az, (n_f, n_l)))
    d = directions(az_rad[f_i, k_i], np.radians(el)[p_i])
    xyz = d * rng_m[f_i, k_i, p_i][:, None]
    fields: dict[str, np.ndarray] = {
        "frame": f_i.astype(np.int32),
        "line": k_i.astype(np.int32),
        "pixel": p_i.astype(np.int32),
    }
    return TimedCloud(xyz_m=np.asarray(xyz, dtype=float), t_s=t[f_i, k_i].astype(float), fields=fields)


def _npz_members(path: Path) -> list[zipfile.ZipInfo]:
    try:
        with zipfile.ZipFile(path) as z:
            return z.infolist()
    except (zipfile.BadZipFile, OSError) as exc:
        raise MalformedInputError(f"not an NPZ (zip) archive: {exc}", field="file") from None


def _npz_names(path: Path) -> set[str]:
    return {m.filename.removesuffix(".npy") for m in _npz_members(path)}


def _load_npz(
    path: Path, max_bytes: int, *, required: tuple[str, ...], optional: tuple[str, ...]
) -> dict[str, NDArray[np.float64]]:
    members = _npz_members(path)
    names = {m.filename.removesuffix(".npy") for m in members}
    unknown = sorted(names - set(required) - set(optional))
    if unknown:
        raise MalformedInputError(f"unexpected array(s) in the NPZ: {', '.join(unknown)}", field=unknown[0])
    missing = [k for k in required if k not in names]
    if missing:
        raise MalformedInputError(f"the NPZ lacks {', '.join(missing)}", field=missing[0])
    declared = sum(m.file_size for m in members)
    if declared > max_bytes:
        raise LimitExceededError(f"the NPZ would expand to {declared} bytes; the limit is {max_bytes}", field="file")
    try:
        with np.load(path, allow_pickle=False) as npz:
            return {k: np.asarray(npz[k], dtype=float) for k in (*required, *optional) if k in names}
    except (ValueError, OSError, zipfile.BadZipFile) as exc:
        raise MalformedInputError(f"the NPZ could not be read: {exc}", field="file") from None
