"""Files in, motion (and rectified cloud) out: what ``tumblescan linescan-motion estimate``
and the ``linescan-motion`` job both run, so the two can never drift apart.

Recipe for tracks: read and validate the tracks, estimate, rectify the optional cloud.
Recipe for frames: split the cloud into frames and lines, estimate, rectify every point.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from .._typing import Progress, no_progress
from ..errors import InputError, MalformedInputError
from ..io.ply import TimedCloud, read_ply
from ..io.sniff import sniff
from .options import FramesOptions, TracksOptions
from .result import MotionResult

if TYPE_CHECKING:
    from .tracks import Tracks

InputForm = Literal["tracks", "frames"]


@dataclass(frozen=True)
class Outcome:
    """An estimate, the cloud it was made from or came with (None for tracks alone), that
    cloud rectified to the result's reference time, and the tracks it came from (None for frames)."""

    result: MotionResult
    cloud: TimedCloud | None
    rectified: TimedCloud | None
    tracks: Tracks | None = None


def input_form(path: Path, *, field: str = "file") -> InputForm:
    """'tracks' (JSON or CSV) or 'frames' (PLY or NPZ), from the file's first bytes."""
    if path.is_file() and path.stat().st_size == 0:
        raise MalformedInputError(f"{path.name} is empty (0 bytes)", field=field)
    kind = sniff(path)
    if kind in ("ply", "zip"):
        return "frames"
    if kind == "json" or (kind == "text" and _starts_with_track_header(path)):
        return "tracks"
    claimed = path.suffix.lower().lstrip(".")
    if claimed in ("ply", "npz", "json", "csv"):
        raise MalformedInputError(
            f"{path.name} is named .{claimed} but is not a {claimed.upper()} file (its first bytes say otherwise)",
            field=field,
        )
    raise MalformedInputError(
        f"{path.name} is neither tracks (JSON, CSV) nor frames (PLY, NPZ with per-point times)", field=field
    )


def estimate_tracks(
    tracks_path: Path, options: TracksOptions, *, cloud_path: Path | None = None, progress: Progress = no_progress
) -> Outcome:
    """Motion from feature tracks; the cloud, if given, rectified with it."""
    from .sparse.estimate import estimate_motion
    from .tracks_io import read_tracks

    # 1. Read and validate the tracks, and the cloud before the work: a bad cloud fails at once.
    progress("loading", 0.0)
    tracks = read_tracks(tracks_path)
    cloud = _read_cloud(cloud_path) if cloud_path is not None else None
    # 2. Estimate, reporting through the attempts (each report is a cancellation point).
    result = estimate_motion(tracks, options, progress=lambda stage, f: progress(stage, 0.02 + 0.9 * f))
    if cloud is None:
        return Outcome(result, None, None, tracks)
    # 3. Rectify the cloud that came with the tracks.
    progress("rectifying", 0.93)
    return Outcome(result, cloud, rectified(cloud, result), tracks)


def _read_cloud(path: Path) -> TimedCloud:
    """The cloud that comes with tracks; its errors name it (the tracks are the main input)."""
    try:
        return read_ply(path)
    except InputError as exc:
        raise type(exc)(f"cloud {path.name}: {exc}", field="cloud") from None


def estimate_frames(path: Path, options: FramesOptions, *, progress: Progress = no_progress) -> Outcome:
    """Motion from dense frames (PLY or NPZ with per-point times), every point rectified."""
    from .dense.estimate import estimate_from_frames
    from .frames import read_frames

    # 1. Split the cloud into frames and lines.
    progress("assembling", 0.0)
    frames = read_frames(path, frame_period_s=options.frame_period_s)
    # 2-4. Register, initialize and refine (stages reported by the estimator).
    result = estimate_from_frames(frames, options, progress=lambda stage, f: progress(stage, 0.02 + 0.9 * f))
    # 5. Rectify every point to the reference time.
    progress("rectifying", 0.93)
    return Outcome(result, frames.cloud, rectified(frames.cloud, result))


def rectified(cloud: TimedCloud, result: MotionResult) -> TimedCloud:
    """``cloud`` mapped to the result's reference time, every original field kept."""
    from .rectify import rectify

    xyz = rectify(cloud.xyz_m, cloud.t_s, result.motion(), to_time_s=result.reference_time_s)
    return TimedCloud(xyz, cloud.t_s, cloud.fields)


def _starts_with_track_header(path: Path) -> bool:
    with open(path, "rb") as fh:
        return fh.read(64).lstrip().lower().startswith(b"track")
