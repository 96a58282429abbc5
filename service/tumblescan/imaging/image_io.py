"""Reading and writing 8/16-bit grayscale images (PNG via OpenCV, TIFF via tifffile)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._typing import FloatArray
from ..errors import InputError

MIN_SIDE_PX = 64
MAX_PIXELS = 64_000_000


class UnreadableImageError(InputError):
    code = "unreadable_image"


def write_image(path: Path, image: np.ndarray) -> None:
    """Write a uint8/uint16 grayscale image; ``.tif``/``.tiff`` go through tifffile, the rest through OpenCV."""
    if path.suffix.lower() in (".tif", ".tiff"):
        import tifffile

        tifffile.imwrite(path, image)
        return
    import cv2

    if not cv2.imwrite(str(path), image):
        raise OSError(f"could not write {path}")


def _quiet_cv2() -> None:
    """OpenCV's decoder logs a warning on stderr for a truncated file (``PNG input buffer is
    incomplete``) before returning nothing; this module says what is wrong itself, in one
    line, so OpenCV keeps only its errors."""
    import cv2

    logging = getattr(getattr(cv2, "utils", None), "logging", None)
    if logging is not None:
        logging.setLogLevel(logging.LOG_LEVEL_ERROR)


TIFF_MAGIC = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")  # classic and BigTIFF, both byte orders


def _declared_px(path: Path, data: np.ndarray) -> int | None:
    """The pixel count the file's header declares (PNG: IHDR, bytes 16-23; TIFF: the first
    series' shape, read from its tags without decoding), or None when it says none."""
    if data.size >= 24 and data[:8].tobytes() == b"\x89PNG\r\n\x1a\n":
        head = data[16:24].tobytes()
        return int.from_bytes(head[:4], "big") * int.from_bytes(head[4:], "big")
    if data[:4].tobytes() in TIFF_MAGIC:
        try:
            import tifffile

            with tifffile.TiffFile(path) as tif:
                return int(np.prod(tif.series[0].shape[:2], dtype=np.int64)) if tif.series else None
        except Exception:  # a header tifffile cannot parse: the decoder below refuses the file
            return None
    return None


def read_image(path: Path, field: str = "image") -> np.ndarray:
    """The image's pixel array as stored (uint8/uint16, (H, W) or (H, W, C)); ``UnreadableImageError``
    when the file is missing or not an image OpenCV or tifffile can decode. A PNG or TIFF whose
    header declares more than ``MAX_PIXELS`` is refused before it is decoded (a compressed file
    of a few hundred kB can declare gigabytes of pixels)."""
    import cv2

    if not path.is_file():
        raise UnreadableImageError(f"{field}: no such file {path}", field=field)
    _quiet_cv2()
    data = np.fromfile(path, dtype=np.uint8)
    declared = _declared_px(path, data)
    if declared is not None and declared > MAX_PIXELS:
        limit = MAX_PIXELS // 1_000_000
        raise InputError(f"{field}: {path.name} declares {declared} px, over the {limit} Mpx limit", field=field)
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if img is None and data[:4].tobytes() in TIFF_MAGIC:
        try:
            import tifffile

            img = tifffile.imread(path)
        except Exception:  # tifffile raises many kinds on broken files; all mean unreadable
            img = None
    if img is None:
        raise UnreadableImageError(f"{field}: {path.name} is not a readable PNG or TIFF image", field=field)
    return np.asarray(img)


def to_gray(img: np.ndarray, field: str = "image") -> FloatArray:
    """A grayscale float image (DN) from a stored array: 1 channel as is, 3 (BGR, as OpenCV reads)
    as Rec. 601 luminance. ``InputError`` for floats, over 3 channels, sides under 64 px or over
    64 Mpx."""
    if not np.issubdtype(img.dtype, np.integer) and img.dtype != np.bool_:
        raise InputError(f"{field}: pixel type {img.dtype} is not supported (8- or 16-bit integers only)", field=field)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim == 3:
        if img.shape[2] != 3:
            raise InputError(f"{field}: {img.shape[2]} channels (1 or 3 expected)", field=field)
        b, g, r = (img[:, :, i].astype(float) for i in range(3))
        gray = 0.114 * b + 0.587 * g + 0.299 * r
    elif img.ndim == 2:
        gray = img.astype(float)
    else:
        raise InputError(f"{field}: array of {img.ndim} dimensions is not an image", field=field)
    h, w = gray.shape
    if min(h, w) < MIN_SIDE_PX:
        raise InputError(f"{field}: {w}x{h} px is under the {MIN_SIDE_PX} px minimum side", field=field)
    if h * w > MAX_PIXELS:
        raise InputError(f"{field}: {w}x{h} px is over the 64 Mpx limit", field=field)
    return gray
