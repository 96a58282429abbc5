"""Files in, files out: read the markers (and an optional layout), estimate, write result.json
(and an HTML report). Shared by the CLI and the job."""

from __future__ import annotations

import json
from pathlib import Path

from .._typing import Progress, no_progress
from .estimate import estimate_poses
from .markers_io import MarkerInput, read_markers
from .options import ImagePoseOptions, MarkerPoseLimits, MarkerPoseOptions, TagPoseOptions
from .result import MarkerPoseResult
from .simulate import SimConfig, Simulation, simulate
from .tag_estimate import estimate_tag_poses
from .tag_simulate import TagSimConfig, TagSimulation, simulate_tags
from .tags_io import FORMAT as TAGS_FORMAT
from .tags_io import read_tags


def input_level(path: Path) -> str:
    """'A' (markers JSON or CSV), 'B' (a tumblescan.tags.v1 JSON) or 'C' (a zip or a directory of
    images with scene.json), from the first bytes (names are not trusted). Only a file named .zip
    whose content is neither a zip nor a tags document is taken at its name's word: level C, whose
    reader says it is not a readable zip (as the API's images part does), rather than level A's,
    which would say it is neither markers JSON nor CSV."""
    if path.is_dir():
        return "C"
    with open(path, "rb") as fh:
        head = fh.read(4096)
    if head.startswith(b"PK\x03\x04"):
        return "C"
    if TAGS_FORMAT.encode() in head:
        return "B"
    return "C" if path.suffix.lower() == ".zip" else "A"


def run_tags(
    tags: Path,
    *,
    options: TagPoseOptions | None = None,
    limits: MarkerPoseLimits | None = None,
    progress: Progress = no_progress,
) -> MarkerPoseResult:
    return estimate_tag_poses(read_tags(tags, limits), options, progress)


def load_input(
    markers: Path,
    layout: Path | None = None,
    options: MarkerPoseOptions | None = None,
    limits: MarkerPoseLimits | None = None,
) -> MarkerInput:
    """Read and validate (every refusal is an ``InputError`` naming the field)."""
    options = options or MarkerPoseOptions()
    return read_markers(markers, layout_path=layout, point_sigma_m=options.point_sigma_m, limits=limits)


def run(
    markers: Path,
    *,
    layout: Path | None = None,
    options: MarkerPoseOptions | None = None,
    limits: MarkerPoseLimits | None = None,
    progress: Progress = no_progress,
) -> MarkerPoseResult:
    options = options or MarkerPoseOptions()
    data = load_input(markers, layout, options, limits)
    return estimate_poses(data, options, progress)


def write_simulation(out: Path, config: SimConfig, seed: int) -> tuple[Path, Path]:
    """Simulate level A and write markers.json and truth.json into ``out``."""
    return _write(out, "markers.json", simulate(config, seed), seed)


def write_tag_simulation(out: Path, config: TagSimConfig, seed: int) -> tuple[Path, Path]:
    """Simulate level B and write tags.json and truth.json into ``out``."""
    return _write(out, "tags.json", simulate_tags(config, seed), seed)


def _write(out: Path, name: str, sim: Simulation | TagSimulation, seed: int) -> tuple[Path, Path]:
    out.mkdir(parents=True, exist_ok=True)
    (out / name).write_text(json.dumps(sim.document()))
    truth = sim.truth()
    truth["seed"] = seed
    (out / "truth.json").write_text(json.dumps(truth))
    return out / name, out / "truth.json"


def run_images(
    images: Path,
    *,
    options: ImagePoseOptions | None = None,
    limits: MarkerPoseLimits | None = None,
    progress: Progress = no_progress,
) -> MarkerPoseResult:
    """Level C: detect the tags in every image of a zip or directory, then level B."""
    import time

    import numpy as np

    from .errors import TooFewFramesError
    from .images_io import detect_tags, read_image_set

    options = options or ImagePoseOptions()
    image_set = read_image_set(images, limits)
    clock = time.perf_counter()
    data, info = detect_tags(image_set, options, progress)
    timing = {"detect_s": time.perf_counter() - clock}
    n = len(np.unique(data.det_frame))
    if n < 3:
        raise TooFewFramesError(f"tags of the layout were found in {n} frames; at least 3 are needed", field="images")
    return estimate_tag_poses(data, options, progress, level="C", detection=info, timing=timing)
