"""The shared imaging package: camera conventions, the renderer's geometry, image files, edges."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tumblescan.errors import InputError
from tumblescan.imaging.camera import PinholeCamera, camera_from_fov
from tumblescan.imaging.image_io import UnreadableImageError, read_image, to_gray, write_image
from tumblescan.imaging.lines import edge_points, fit_line
from tumblescan.imaging.mesh import box
from tumblescan.imaging.render import render


def test_projection_and_back_projection_invert_each_other_with_centres_at_integers() -> None:
    cam = PinholeCamera(640, 480, 800.0, 810.0, 319.5, 239.5, skew=0.5)
    assert np.allclose(cam.project(np.array([[0.0, 0.0, 5.0]])), [[319.5, 239.5]])  # the image centre
    uv = np.array([[0.0, 0.0], [639.0, 479.0], [100.25, 300.75]])
    p = cam.rays(uv) * 7.0
    assert np.allclose(cam.project(p), uv, atol=1e-9)


def test_undistort_inverts_opencv_distortion() -> None:
    import cv2

    cam = PinholeCamera(640, 480, 800.0, 800.0, 319.5, 239.5, distortion=(-0.2, 0.05, 0.001, -0.001, 0.0))
    ideal = np.array([[100.0, 50.0], [500.0, 400.0], [320.0, 240.0]])
    p = np.ascontiguousarray(cam.rays(ideal).reshape(-1, 1, 3))
    measured, _ = cv2.projectPoints(p, np.zeros((3, 1)), np.zeros((3, 1)), cam.K, np.array(cam.distortion))
    assert np.allclose(cam.undistort(np.asarray(measured, dtype=float).reshape(-1, 2)), ideal, atol=1e-3)


@pytest.mark.parametrize("half_width_m", [1.0, 1.07, 1.13])
def test_a_rendered_plate_has_its_edge_where_the_camera_puts_it_to_a_hundredth_of_a_pixel(half_width_m: float) -> None:
    import cv2

    # A plate 600 km away (float32 alone would round it to ~6 cm), turned 7° in the image so the
    # edge crosses the 4x4 sub-sample grid at every phase, blurred by a 0.6 px PSF.
    cam = camera_from_fov(256, 256, 0.0004)
    a = np.radians(7.0)
    R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    t = np.array([0.0, 0.0, 600e3])
    plate = box((0.0, 0.0, 0.0), (2 * half_width_m, 2.0, 0.02), albedo=1.0)
    img = render(plate, cam, R, t, np.array([0.0, 0.0, -1.0])).radiance
    assert img[128, 128] == pytest.approx(1.04, abs=1e-6)  # lit face-on, plus ambient
    assert img[3, 3] == 0.0
    img = np.asarray(cv2.GaussianBlur(img, (0, 0), 0.6), dtype=float)
    ends = cam.project(np.array([R @ [half_width_m, y, -0.01] + t for y in (-0.6, 0.6)]))
    line = fit_line(edge_points(img, ends.ravel()).uv_px)
    assert line is not None
    assert abs(line.normal @ (line.centroid_px - ends[0])) < 0.01
    assert abs(line.normal @ (ends[1] - ends[0])) / np.linalg.norm(ends[1] - ends[0]) < np.radians(0.02)


@pytest.mark.parametrize(("suffix", "dtype"), [(".png", np.uint8), (".png", np.uint16), (".tif", np.uint16)])
def test_images_round_trip(tmp_path: Path, suffix: str, dtype: type) -> None:
    a: np.ndarray = (np.arange(80 * 96).reshape(80, 96) % 250).astype(dtype)
    write_image(tmp_path / f"x{suffix}", a)
    b = read_image(tmp_path / f"x{suffix}")
    assert b.dtype == dtype and np.array_equal(a, b)


def test_unreadable_and_refused_images(tmp_path: Path) -> None:
    (tmp_path / "bad.png").write_bytes(b"\x89PNG\r\n\x1a\nnot really")
    with pytest.raises(UnreadableImageError) as exc:
        read_image(tmp_path / "bad.png")
    assert exc.value.code == "unreadable_image"
    with pytest.raises(InputError, match="pixel type float32"):
        to_gray(np.zeros((80, 80), np.float32))
    with pytest.raises(InputError, match="4 channels"):
        to_gray(np.zeros((80, 80, 4), np.uint8))
    with pytest.raises(InputError, match="minimum side"):
        to_gray(np.zeros((80, 40), np.uint8))
    rgb = np.zeros((70, 70, 3), np.uint8)
    rgb[..., 2] = 100  # red in OpenCV's BGR order
    assert to_gray(rgb)[0, 0] == pytest.approx(29.9)


def test_a_truncated_png_is_refused_in_one_line_without_opencvs_warning(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    write_image(tmp_path / "x.png", (np.arange(96 * 96).reshape(96, 96) % 250).astype(np.uint8))
    data = (tmp_path / "x.png").read_bytes()
    (tmp_path / "cut.png").write_bytes(data[: len(data) // 2])
    capfd.readouterr()
    with pytest.raises(UnreadableImageError):
        read_image(tmp_path / "cut.png")
    assert capfd.readouterr().err == ""  # OpenCV printed "PNG input buffer is incomplete" on stderr


def test_a_png_declaring_too_many_pixels_is_refused_before_decoding(tmp_path: Path) -> None:
    import struct
    import zlib

    ihdr = struct.pack(">IIBBBBB", 100_000, 100_000, 8, 0, 0, 0, 0)  # 10 Gpx, 8-bit gray
    chunk = struct.pack(">I", len(ihdr)) + b"IHDR" + ihdr + struct.pack(">I", zlib.crc32(b"IHDR" + ihdr))
    (tmp_path / "bomb.png").write_bytes(b"\x89PNG\r\n\x1a\n" + chunk)
    with pytest.raises(InputError, match=r"declares 10000000000 px, over the 64 Mpx limit"):
        read_image(tmp_path / "bomb.png")


def test_a_tiff_declaring_too_many_pixels_is_refused_before_decoding(tmp_path: Path) -> None:
    import tifffile

    # 8000 x 8200 zeros, zlib-tiled: about 0.1 MB on disk for 65.6 Mpx (just over the limit).
    tifffile.imwrite(tmp_path / "big.tif", np.zeros((8000, 8200), np.uint8), compression="zlib", tile=(1024, 1024))
    with pytest.raises(InputError, match=r"declares 65600000 px, over the 64 Mpx limit"):
        read_image(tmp_path / "big.tif")
