"""Level C input: a zip (or a directory) holding ``scene.json`` (level B's document without
detections, with ``frames``) and ``images/<camera>/<frame:06d>.png`` (8- or 16-bit grey), read in
place (the zip is never extracted); then the tags detected in every image become level B's
detections.

Refusals: a zip that cannot be read, unsafe or too many members, an unpacked size over the
limit, a member that is not a readable image, an image whose size differs from its camera's, an
image of an unknown camera or frame, and the scene's own refusals (``tags_io``).
"""

from __future__ import annotations

import re
import time
import zipfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._typing import Progress, no_progress
from ..imaging.image_io import UnreadableImageError
from ..io.json_text import parse_json
from .errors import InputError, LimitExceededError, MalformedInputError
from .markers_io import _load_json
from .options import ImagePoseOptions, MarkerPoseLimits
from .result import DetectionInfo
from .tag_detect import TagDetector
from .tags_io import TagInput, tags_from_json

SCENE = "scene.json"
IMAGE_NAME = re.compile(r"^images/([^/]+)/(\d{6})\.(png|tif|tiff)$")
MAX_UNPACKED_RATIO = 200


class ImageSizeError(InputError):
    code = "image_size_mismatch"


@dataclass
class ImageSet:
    """The scene and where each (camera index, frame index) image is: a zip member or a file."""

    scene: TagInput
    source: Path
    members: dict[tuple[int, int], str]  # (camera, frame index) -> member name (relative path)

    def read(self, key: tuple[int, int]) -> np.ndarray:
        """One image, decoded (a zip is opened for it alone: to read many, iterate ``decoded``)."""
        with self._reader() as raw:
            return self._decode(key, raw(self.members[key]))

    def decoded(self) -> Iterator[tuple[tuple[int, int], np.ndarray]]:
        """Every (camera, frame) key with its image, in frame order. A zip is opened once for all of
        them: each open re-reads the member list (about 57 ms for 20,000 members)."""
        with self._reader() as raw:
            for key in self:
                yield key, self._decode(key, raw(self.members[key]))

    @contextmanager
    def _reader(self) -> Iterator[Callable[[str], bytes]]:
        """A member's bytes by name, from the directory or the zip held open meanwhile."""
        if self.source.is_dir():
            source = self.source
            yield lambda name: (source / name).read_bytes()
        else:
            with zipfile.ZipFile(self.source) as zf:
                yield zf.read

    def _decode(self, key: tuple[int, int], data: bytes) -> np.ndarray:
        """The image as 8-bit grey (16-bit images are scaled by their maximum)."""
        import cv2

        name = self.members[key]
        img = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED) if data else None
        if img is None or img.ndim != 2 or img.dtype not in (np.uint8, np.uint16):
            raise UnreadableImageError(f"{name} is not a readable 8- or 16-bit grey PNG or TIFF", field=name)
        cam = self.scene.cameras[key[0]]
        if img.shape != (cam.height_px, cam.width_px):
            raise ImageSizeError(
                f"{name} is {img.shape[1]}x{img.shape[0]} px; camera {cam.id} is {cam.width_px}x{cam.height_px}",
                field=name,
            )
        if img.dtype == np.uint16:
            img = np.round(img.astype(float) * (255.0 / max(float(img.max()), 1.0))).astype(np.uint8)
        return np.asarray(img)

    def __iter__(self) -> Iterator[tuple[int, int]]:
        return iter(sorted(self.members, key=lambda k: (k[1], k[0])))


def read_image_set(path: Path, limits: MarkerPoseLimits | None = None, field: str = "images") -> ImageSet:
    """Read the scene and index the images of a zip or a directory (the images are decoded later)."""
    limits = limits or MarkerPoseLimits()
    if path.is_dir():
        names = [p.relative_to(path).as_posix() for p in sorted(path.rglob("*")) if p.is_file()]
        if SCENE not in names:
            raise MalformedInputError(f"{field}: no {SCENE} in the directory", field=field)
        scene_doc = _load_json(path / SCENE, SCENE)
    else:
        names, scene_bytes = _zip_index(path, limits, field)
        scene_doc = parse_json(scene_bytes, SCENE, error=MalformedInputError)
    scene = tags_from_json(scene_doc, limits=limits, require_detections=False)
    cam_index = {c.id: i for i, c in enumerate(scene.cameras)}
    frame_index = {int(f): i for i, f in enumerate(scene.frames)}
    members: dict[tuple[int, int], str] = {}
    for name in names:
        if name == SCENE or name.endswith("/"):
            continue
        m = IMAGE_NAME.match(name)
        if m is None:
            raise MalformedInputError(f"{name}: images must be images/<camera>/<frame:06d>.png (or .tif)", field=name)
        cam, frame = m.group(1), int(m.group(2))
        if cam not in cam_index:
            raise MalformedInputError(f"{name}: camera {cam!r} is not in the scene's cameras", field=name)
        if frame not in frame_index:
            raise MalformedInputError(f"{name}: frame {frame} is not in the scene's frames", field=name)
        members[(cam_index[cam], frame_index[frame])] = name
    if not members:
        raise MalformedInputError(f"{field}: no images/<camera>/<frame:06d>.png", field=field)
    if len(members) > limits.max_images:
        raise LimitExceededError(f"{len(members)} images; the limit is {limits.max_images}", field=field)
    return ImageSet(scene, path, members)


def _zip_index(path: Path, limits: MarkerPoseLimits, field: str) -> tuple[list[str], bytes]:
    """Member names and the scene's bytes; refuses unsafe, too many or too large members."""
    if path.stat().st_size > limits.max_archive_bytes:
        raise LimitExceededError(f"{field}: {path.stat().st_size} bytes is over the limit", field=field)
    try:
        zf = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as exc:
        raise MalformedInputError(f"{field}: not a readable zip ({exc})", field=field) from None
    with zf:
        infos = zf.infolist()
        if len(infos) > limits.max_images + 16:
            raise LimitExceededError(f"{field}: {len(infos)} members; the limit is {limits.max_images}", field=field)
        total = sum(i.file_size for i in infos)
        packed = max(sum(i.compress_size for i in infos), 1)
        if total > 4 * limits.max_archive_bytes or total / packed > MAX_UNPACKED_RATIO:
            raise LimitExceededError(f"{field}: {total} bytes unpacked: refused as a zip bomb", field=field)
        names = [i.filename for i in infos]
        for name in names:
            if name.startswith("/") or ".." in name.split("/") or "\\" in name:
                raise MalformedInputError(f"{field}: member {name!r} has an unsafe path", field=field)
        if SCENE not in names:
            raise MalformedInputError(f"{field}: no {SCENE} in the zip", field=field)
        return names, zf.read(SCENE)


def check_images(images: ImageSet, progress: Progress = no_progress) -> None:
    """Decode every image once (unreadable files and wrong sizes are refused now, naming the file)."""
    for n, _ in enumerate(images.decoded()):
        if n % 50 == 0:
            progress("checking images", 0.05 * n / max(len(images.members), 1))


def detect_tags(
    images: ImageSet, options: ImagePoseOptions | None = None, progress: Progress = no_progress
) -> tuple[TagInput, DetectionInfo]:
    """Level B's input from the images: every image's detections of the layout's family, with
    their corners in the contract's convention (``tag_detect``)."""
    options = options or ImagePoseOptions()
    scene = images.scene
    detector = TagDetector(options.detector, scene.family, options.quad_decimate)
    started = time.perf_counter()
    rows: list[tuple[int, int, int, np.ndarray]] = []
    found = 0
    per_camera = dict.fromkeys((c.id for c in scene.cameras), 0)
    tag_index = {t: i for i, t in enumerate(scene.tag_ids)}
    n_images = len(images.members)
    last: dict[int, tuple[int, np.ndarray]] = {}  # camera -> (frame index, corners found there (n, 2))
    full_frames = 0
    for n, ((c, f), image) in enumerate(images.decoded()):
        roi = _roi(last.get(c), f, image.shape) if options.roi_tracking else None
        if roi is None:
            full_frames += 1
            detections = detector.detect(image)
        else:
            x0, y0, x1, y1 = roi
            detections = detector.detect(np.ascontiguousarray(image[y0:y1, x0:x1]))
            for d in detections:  # crop pixels to image pixels: a shift by the crop's corner, exactly
                d.corners_px = d.corners_px + np.array([x0, y0], dtype=float)
        known = [d for d in detections if d.id in tag_index]
        found += len(detections)
        for d in known:
            rows.append((f, c, tag_index[d.id], d.corners_px))
            per_camera[scene.cameras[c].id] += 1
        if known:
            last[c] = (f, np.concatenate([d.corners_px for d in known]))
        else:
            last.pop(c, None)
        if n % 10 == 0:
            progress("detecting tags", 0.05 + 0.25 * n / max(n_images, 1))
    rows.sort(key=lambda r: (r[0], r[1], r[2]))
    data = TagInput(
        cameras=scene.cameras,
        family=scene.family,
        size_m=scene.size_m,
        tag_ids=scene.tag_ids,
        T_body_tag=scene.T_body_tag,
        frames=scene.frames,
        t_s=scene.t_s,
        det_frame=np.array([r[0] for r in rows], dtype=np.int64),
        det_cam=np.array([r[1] for r in rows], dtype=np.int64),
        det_tag=np.array([r[2] for r in rows], dtype=np.int64),
        corners_px=np.array([r[3] for r in rows], dtype=float).reshape(-1, 4, 2),
        frame_rate_hz=scene.frame_rate_hz,
        warnings=list(scene.warnings),
    )
    if found > len(rows):
        data.warnings.append(f"{found - len(rows)} detections of tags not in the layout were ignored")
    if options.roi_tracking:
        data.warnings.append(
            f"tags were searched for around the last frame's tags in {n_images - full_frames} of {n_images} images"
        )
    info = DetectionInfo(
        detector="pupil-apriltags" if options.detector == "apriltag" else "opencv aruco",
        images=n_images,
        detections=found,
        known_tags=len(rows),
        per_camera=per_camera,
        time_s=time.perf_counter() - started,
    )
    return data, info


ROI_FULL_EVERY = 10  # every this many frames a camera's whole image is searched (tags entering the view)
ROI_MARGIN = 0.5  # of the last tags' extent, on each side
ROI_MIN_MARGIN_PX = 40


def _roi(last: tuple[int, np.ndarray] | None, frame: int, shape: tuple[int, ...]) -> tuple[int, int, int, int] | None:
    """The crop (x0, y0, x1, y1) to search in ``frame`` around the tags this camera found in the
    previous frame (grown by half their extent, at least 40 px, on each side), or None for the
    whole image: no tags last frame, a gap, or every ``ROI_FULL_EVERY`` frames."""
    if last is None or last[0] != frame - 1 or frame % ROI_FULL_EVERY == 0:
        return None
    lo, hi = last[1].min(axis=0), last[1].max(axis=0)
    grow = np.maximum(ROI_MARGIN * (hi - lo), ROI_MIN_MARGIN_PX)
    x0, y0 = np.floor(lo - grow).astype(int)
    x1, y1 = np.ceil(hi + grow).astype(int) + 1
    H, W = shape[:2]
    return max(x0, 0), max(y0, 0), min(x1, W), min(y1, H)
