"""Files in, files out: a directory or zip with meta.json and its frames, validated; the estimate;
result.json (shared by the CLI and the job)."""

from __future__ import annotations

import dataclasses
import json
import zipfile
from pathlib import Path

import numpy as np

from .._typing import Progress, no_progress
from ..errors import InputError, LimitExceededError
from ..imaging.image_io import read_image, to_gray
from .estimate import Sequence, estimate_spin
from .meta import MIN_SIDE_PX, MetaOptions, SpinInput, read_meta
from .options import EstimateOptions
from .result import SpinResult

MAX_ZIP_MEMBERS = 2000
MAX_ZIP_BYTES = 2_000_000_000
MAX_ZIP_RATIO = 200


def load_input(meta_path: Path, frame_files: dict[str, Path] | None = None) -> Sequence:
    """Validate meta.json and read its frames (``frame_files``: file name in meta -> path, else
    relative to meta.json). Every ``invalid_input`` and ``unreadable_image`` is raised here."""
    meta = read_meta(meta_path)
    if frame_files is not None:
        _refuse_unlisted(frame_files, [fr.file for fr in meta.frames])
    grays, full = [], 255.0
    for i, fr in enumerate(meta.frames):
        field = f"frames.{i}.file"
        path = _frame_path(meta_path, fr.file, frame_files)
        if path is not None and path.is_dir():  # it is in the input, as a directory: say so
            raise InputError(f"{field}: {fr.file} is a directory, not an image file", field=field)
        if path is None or not path.is_file():
            raise InputError(f"{field}: {fr.file} is not in the input", field=field)
        raw = read_image(path, field=field)
        gray = _to_gray(raw, field)
        h, w = gray.shape
        if (w, h) != (meta.camera.width_px, meta.camera.height_px):
            raise InputError(
                f"camera.width_px: {fr.file} is {w}x{h} px, "
                f"meta.json says {meta.camera.width_px}x{meta.camera.height_px}",
                field="camera.width_px",
            )
        full = max(full, float(np.iinfo(raw.dtype).max) if np.issubdtype(raw.dtype, np.integer) else 255.0)
        grays.append(gray)
    return Sequence(grays, np.array([f.t_s for f in meta.frames]), full, meta)


def _refuse_unlisted(frame_files: dict[str, Path], listed: list[str]) -> None:
    """An uploaded frame meta.json does not list is a mistake (a wrong or renamed file), not
    something to ignore silently."""
    known = set(listed) | {Path(name).name for name in listed}
    unlisted = sorted(name for name in frame_files if name not in known)
    if unlisted:
        more = f" (and {len(unlisted) - 1} more)" if len(unlisted) > 1 else ""
        raise InputError(f"frames: {unlisted[0]}{more} is not listed in meta.json's frames", field="frames")


def _frame_path(meta_path: Path, name: str, frame_files: dict[str, Path] | None) -> Path | None:
    if frame_files is not None:
        return frame_files.get(name) or frame_files.get(Path(name).name)
    return meta_path.parent / name


def _to_gray(raw: np.ndarray, field: str) -> np.ndarray:
    """imaging's to_gray with this kind's 32 px minimum side."""
    if min(raw.shape[:2]) < MIN_SIDE_PX:
        raise InputError(
            f"{field}: {raw.shape[1]}x{raw.shape[0]} px is under the {MIN_SIDE_PX} px minimum side", field=field
        )
    if min(raw.shape[:2]) < 64:  # to_gray's own minimum is 64 px; pad is not wanted, so convert here
        return np.asarray(raw if raw.ndim == 2 else raw[..., 0], dtype=float)
    return to_gray(raw, field=field)


def unpack_zip(archive: Path, dest: Path, field: str = "archive") -> Path:
    """Extract a zip safely (no absolute paths, no '..', no links, member count, size and ratio
    limits against zip bombs) into ``dest``; returns the meta.json inside (at the top or one level down)."""
    try:
        zf = zipfile.ZipFile(archive)
    except (zipfile.BadZipFile, OSError) as exc:
        raise InputError(f"{field}: not a readable zip ({exc})", field=field) from None
    with zf:
        infos = zf.infolist()
        if len(infos) > MAX_ZIP_MEMBERS:
            raise LimitExceededError(f"{field}: {len(infos)} members (limit {MAX_ZIP_MEMBERS})", field=field)
        total = sum(i.file_size for i in infos)
        packed = max(sum(i.compress_size for i in infos), 1)
        if total > MAX_ZIP_BYTES or total / packed > MAX_ZIP_RATIO:
            raise LimitExceededError(
                f"{field}: {total} bytes unpacked ({total / packed:.0f}x): refused as a zip bomb", field=field
            )
        root = dest.resolve()
        for info in infos:
            name = info.filename
            p = Path(name)
            if p.is_absolute() or ".." in p.parts or "\\" in name or (info.external_attr >> 16) & 0o170000 == 0o120000:
                raise InputError(f"{field}: member {name!r} has an unsafe path", field=field)
            target = (root / p).resolve()
            if not target.is_relative_to(root):
                raise InputError(f"{field}: member {name!r} has an unsafe path", field=field)
            if info.is_dir():
                continue
            target.parent.mkdir(parents=True, exist_ok=True)
            with zf.open(info) as src, target.open("wb") as out:
                left = info.file_size + 1
                while chunk := src.read(1 << 20):
                    left -= len(chunk)
                    if left < 0:
                        raise LimitExceededError(f"{field}: member {name!r} is larger than declared", field=field)
                    out.write(chunk)
    for cand in [dest / "meta.json", *sorted(dest.glob("*/meta.json"))]:
        if cand.is_file():
            return cand
    raise InputError(f"{field}: no meta.json in the zip", field=field)


def resolve_input(path: Path, workdir: Path) -> Path:
    """meta.json of a directory, a meta.json path, or a zip (unpacked under ``workdir``)."""
    if path.is_dir():
        return path / "meta.json"
    if path.suffix.lower() == ".zip" or (path.is_file() and path.read_bytes()[:4] == b"PK\x03\x04"):
        return unpack_zip(path, workdir)
    return path


def run(seq: Sequence, options: EstimateOptions | None = None, progress: Progress = no_progress) -> SpinResult:
    """Estimate the spin of a loaded sequence. ``options.return_tracks`` (when given) overrides
    meta.json's for this run only: ``seq`` is left as it was (it was changed in place, so a run
    for a report's tracks leaked them into whatever used ``seq`` next)."""
    opts = options or EstimateOptions()
    if opts.return_tracks is not None and opts.return_tracks != seq.meta.options.return_tracks:
        meta = seq.meta.model_copy(update={"options": MetaOptions(return_tracks=opts.return_tracks)})
        seq = dataclasses.replace(seq, meta=meta)
    return estimate_spin(seq, opts, progress)


def write_result(path: Path, result: SpinResult) -> None:
    """result.json (atomically)."""
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(result.to_json(), indent=2))
    tmp.replace(path)


__all__ = ["SpinInput", "load_input", "resolve_input", "run", "unpack_zip", "write_result"]
