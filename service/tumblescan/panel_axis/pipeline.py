"""Files in, files out: read meta.json and its image, estimate, write result.json (shared by the
CLI and the job)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._typing import FloatArray, Progress, no_progress
from ..errors import InputError
from ..imaging.image_io import read_image, to_gray
from .estimate import estimate_axis
from .meta import PanelAxisInput, check_image_size, read_meta
from .options import EstimateOptions
from .result import PanelAxisResult


@dataclass(frozen=True)
class PanelAxisData:
    """A validated input: meta.json, the grayscale image (DN) and its saturation level."""

    meta: PanelAxisInput
    gray: FloatArray
    full_scale: float
    image_path: Path


def load_input(meta_path: Path, image_path: Path | None = None) -> PanelAxisData:
    """Validate meta.json and its image (``image_path``, else meta's ``image`` relative to meta.json).
    A directory is named as one (the readers call anything that is not a file "no such file", which
    sends the user looking for a typo in a path that exists)."""
    _not_a_directory(meta_path, "meta")
    meta = read_meta(meta_path)
    path = image_path if image_path is not None else meta_path.parent / meta.image
    _not_a_directory(path, "image")
    raw = read_image(path)
    gray = to_gray(raw)
    check_image_size(meta, gray)
    full_scale = float(np.iinfo(raw.dtype).max) if np.issubdtype(raw.dtype, np.integer) else 255.0
    return PanelAxisData(meta, gray, full_scale, path)


def _not_a_directory(path: Path, field: str) -> None:
    if path.is_dir():
        hint = f" (did you mean {path / 'meta.json'}?)" if field == "meta" and (path / "meta.json").is_file() else ""
        raise InputError(f"{field}: {path} is a directory, not a file{hint}", field=field)


def run(
    data: PanelAxisData, options: EstimateOptions | None = None, progress: Progress = no_progress
) -> PanelAxisResult:
    """Estimate the panel axis of a loaded input."""
    return estimate_axis(data.gray, data.meta, options, progress, full_scale=data.full_scale)


def write_result(path: Path, result: PanelAxisResult) -> None:
    """result.json (atomically)."""
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(result.to_json(), indent=2))
    tmp.replace(path)
