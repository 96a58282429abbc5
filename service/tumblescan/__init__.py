"""Tumblescan: motion estimation and rectification for tumbling targets seen by a line-scan lidar.

The numerical core, usable as a library::

    from tumblescan import Scene, random_motion, simulate_tracks, estimate_motion, rectify
    from tumblescan import simulate_frames, read_frames, estimate_from_frames
"""

from .cloud_io import TimedCloud, read_ply, write_ply
from .errors import InputError
from .estimate import EstimateOptions, estimate_motion
from .estimate_frames import estimate_from_frames
from .frames import Frames, assemble_frames, read_frames, read_range_images
from .motion import Motion
from .rectify import distort, rectify
from .result import MotionResult
from .sensor import Scanner, SensorNoise
from .simulate import FrameCloud, Scene, random_motion, simulate_frames, simulate_tracks
from .swarm import SwarmConfig
from .target import SatelliteShape
from .tracks import Tracks
from .tracks_io import read_tracks, tracks_from_csv, tracks_from_json, tracks_to_json, write_tracks

__version__ = "0.1.0"

__all__ = [
    "EstimateOptions",
    "FrameCloud",
    "Frames",
    "InputError",
    "Motion",
    "MotionResult",
    "SatelliteShape",
    "Scanner",
    "Scene",
    "SensorNoise",
    "SwarmConfig",
    "TimedCloud",
    "Tracks",
    "assemble_frames",
    "distort",
    "estimate_from_frames",
    "estimate_motion",
    "random_motion",
    "read_frames",
    "read_ply",
    "read_range_images",
    "read_tracks",
    "rectify",
    "simulate_frames",
    "simulate_tracks",
    "tracks_from_csv",
    "tracks_from_json",
    "tracks_to_json",
    "write_ply",
    "write_tracks",
]
