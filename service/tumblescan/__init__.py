"""Tumblescan: how a space target moves and where it is, with honest uncertainties.

The numerical cores are usable as a library; names load lazily, so ``import tumblescan``
stays cheap (no SciPy, Open3D or OpenCV until a name that needs them is used)::

    from tumblescan import Scene, random_motion, simulate_tracks, estimate_motion, rectify
    from tumblescan import simulate_frames, read_frames, estimate_from_frames

Each job kind lives in its own package (``tumblescan.linescan``, ...); shared code in
``geometry``, ``numerics``, ``io``, ``target`` and ``report``; the job layer, the HTTP API and
the CLI in ``jobs``, ``api`` and ``cli``.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

# Public name -> module that defines it.
_LAZY = {
    "InputError": "errors",
    "TimedCloud": "io.ply",
    "read_ply": "io.ply",
    "write_ply": "io.ply",
    "Motion": "target.motion",
    "SatelliteShape": "target.shape",
    "EstimateOptions": "linescan.options",
    "TracksOptions": "linescan.options",
    "FramesOptions": "linescan.options",
    "MotionResult": "linescan.result",
    "Scanner": "linescan.sensor",
    "SensorNoise": "linescan.sensor",
    "SwarmConfig": "linescan.swarm",
    "Tracks": "linescan.tracks",
    "read_tracks": "linescan.tracks_io",
    "tracks_from_csv": "linescan.tracks_io",
    "tracks_from_json": "linescan.tracks_io",
    "tracks_to_json": "linescan.tracks_io",
    "write_tracks": "linescan.tracks_io",
    "Frames": "linescan.frames",
    "assemble_frames": "linescan.frames",
    "read_frames": "linescan.frames",
    "read_range_images": "linescan.frames",
    "distort": "linescan.rectify",
    "rectify": "linescan.rectify",
    "FrameCloud": "linescan.simulate",
    "Scene": "linescan.simulate",
    "random_motion": "linescan.simulate",
    "simulate_frames": "linescan.simulate",
    "simulate_tracks": "linescan.simulate",
    "estimate_motion": "linescan.sparse.estimate",
    "estimate_from_frames": "linescan.dense.estimate",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module 'tumblescan' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    globals()[name] = value  # later lookups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


if TYPE_CHECKING:
    from .errors import InputError
    from .io.ply import TimedCloud, read_ply, write_ply
    from .linescan.dense.estimate import estimate_from_frames
    from .linescan.frames import Frames, assemble_frames, read_frames, read_range_images
    from .linescan.options import EstimateOptions, FramesOptions, TracksOptions
    from .linescan.rectify import distort, rectify
    from .linescan.result import MotionResult
    from .linescan.sensor import Scanner, SensorNoise
    from .linescan.simulate import FrameCloud, Scene, random_motion, simulate_frames, simulate_tracks
    from .linescan.sparse.estimate import estimate_motion
    from .linescan.swarm import SwarmConfig
    from .linescan.tracks import Tracks
    from .linescan.tracks_io import read_tracks, tracks_from_csv, tracks_from_json, tracks_to_json, write_tracks
    from .target.motion import Motion
    from .target.shape import SatelliteShape
