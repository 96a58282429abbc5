"""Level C's simulator: the level-B scene rendered as grey images of the tagged box.

Per camera and frame: a dark background, the box's faces that turn towards the camera as light
polygons, and each tag (``cv2.aruco.generateImageMarker``, AprilTag 36h11) warped onto its face by
the homography of its corners. Drawn at ``SUPERSAMPLE`` x the resolution over the box's bounding
box only, averaged down (``INTER_AREA``), blurred and given Gaussian read noise. The cameras are
the paper's binned 2 x 2 (1024 x 1024 px, f = 1136 px) without distortion (a plane's image is then
exactly a homography). Pixel convention: OpenCV's, (0, 0) the centre of the top-left pixel; a
supersampled pixel ``X`` has its centre at ``(X + 0.5) / s - 0.5``.

Written as a zip: ``scene.json`` (level B's document without detections, with ``frames``) and
``images/<camera>/<frame:06d>.png`` (8-bit).
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from .._typing import FloatArray
from .tag_camera import RigArrays, body_to_pixels
from .tag_simulate import BOX_HALF_M, TagSimConfig, TagSimulation, simulate_tags, visible_tags

IMAGE_BINNING = 2
IMAGE_TAG_SIZE_M = 0.16  # 40 px at 4.6 m on the binned sensor
# The corner sigma the scene declares: about pupil-apriltags' RMS corner error per axis on these
# renders (0.07-0.09 px against the exact projections in the bench; more on grazing tags).
IMAGE_PIXEL_SIGMA_PX = 0.1
SUPERSAMPLE = 3
MARKER_PX = 80  # the generated marker image (8 cells of 10 px, black border included)
BACKGROUND_DN, FACE_DN, BLACK_DN, WHITE_DN = 25.0, 150.0, 30.0, 220.0
BLUR_SIGMA_PX = 0.6
NOISE_DN = 2.0


def image_config(**kw: object) -> TagSimConfig:
    """The level-C scene: binned cameras, 160 mm tags, no distortion."""
    base: dict[str, object] = {
        "binning": IMAGE_BINNING,
        "tag_size_m": IMAGE_TAG_SIZE_M,
        "distortion": (0.0,) * 5,
        "frames": 20,
        "outlier_fraction": 0.0,
        "miss_fraction": 0.0,
        "gaps": 0,
        "pixel_sigma_px": IMAGE_PIXEL_SIGMA_PX,
    }
    return TagSimConfig.model_validate(base | kw)


def _box_faces() -> list[tuple[FloatArray, FloatArray]]:
    """(outward normal (3,), corners (4, 3) in order around the face) of the box's six faces."""
    h = BOX_HALF_M
    faces = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            a, b = [i for i in range(3) if i != axis]
            corners = []
            for sa, sb in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = np.zeros(3)
                p[axis], p[a], p[b] = sign * h[axis], sa * h[a], sb * h[b]
                corners.append(p)
            n = np.zeros(3)
            n[axis] = sign
            faces.append((n, np.array(corners)))
    return faces


def render_frame(sim: TagSimulation, k: int, c: int, rng: np.random.Generator) -> np.ndarray:
    """Camera ``c``'s 8-bit image (H, W) of frame ``k``."""
    import cv2

    cam = sim.cameras[c]
    rig = RigArrays.of(sim.cameras)
    R, t = sim.R_world_body[k], sim.t_world_m[k]
    H, W = cam.height_px, cam.width_px
    image = np.full((H, W), BACKGROUND_DN)
    box = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * BOX_HALF_M
    uv_box = _pixels(R, t, box, c, rig)
    x0, y0 = np.floor(uv_box.min(axis=0)).astype(int) - 4
    x1, y1 = np.ceil(uv_box.max(axis=0)).astype(int) + 5
    x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, W), min(y1, H)
    if x1 > x0 and y1 > y0:
        s = SUPERSAMPLE
        canvas = np.full(((y1 - y0) * s, (x1 - x0) * s), BACKGROUND_DN, dtype=np.float32)
        origin = np.array([x0, y0], dtype=float)

        def to_canvas(uv: FloatArray) -> FloatArray:
            return np.asarray(s * (uv - origin + 0.5) - 0.5)

        cam_body = R.T @ (cam.t_world_cam - t)  # the camera's position in the body frame
        for n, corners in _box_faces():
            if n @ (cam_body - corners.mean(axis=0)) <= 0:
                continue
            shade = FACE_DN * (0.6 + 0.4 * abs(n @ (cam_body - corners.mean(axis=0))) / np.linalg.norm(cam_body))
            poly = np.round(to_canvas(_pixels(R, t, corners, c, rig)) * 16).astype(np.int32)
            cv2.fillConvexPoly(canvas, poly, float(shade), lineType=cv2.LINE_AA, shift=4)
        for j in range(len(sim.tag_ids)):
            T = sim.T_body_tag[j]
            if T[:3, 2] @ (cam_body - T[:3, 3]) <= 0:
                continue
            _draw_tag(canvas, sim, j, to_canvas(_tag_pixels(sim, j, R, t, c, rig)))
        small = cv2.resize(canvas, (x1 - x0, y1 - y0), interpolation=cv2.INTER_AREA)
        image[y0:y1, x0:x1] = small
    image = cv2.GaussianBlur(image, (0, 0), BLUR_SIGMA_PX)
    image = np.asarray(image, dtype=float) + rng.normal(0.0, NOISE_DN, image.shape)
    return np.asarray(np.clip(np.round(image), 0, 255).astype(np.uint8))


def _pixels(R: FloatArray, t: FloatArray, p_body: FloatArray, c: int, rig: RigArrays) -> FloatArray:
    return np.asarray(body_to_pixels(R[None], t[None], p_body[None], np.array([c]), rig)[0])


def _tag_pixels(sim: TagSimulation, j: int, R: FloatArray, t: FloatArray, c: int, rig: RigArrays) -> FloatArray:
    from .tag_camera import tag_corners_body

    corners = tag_corners_body(sim.T_body_tag[j : j + 1], sim.config.tag_size_m)[0]
    return _pixels(R, t, corners, c, rig)


def _draw_tag(canvas: np.ndarray, sim: TagSimulation, j: int, corners_canvas: FloatArray) -> None:
    """Warp tag ``j``'s marker image, with one white cell of margin, onto ``canvas`` where its
    black square's corners (TL, TR, BR, BL) land at ``corners_canvas`` (4, 2)."""
    import cv2

    marker = _marker_image(sim.tag_ids[j])
    cell = MARKER_PX / 8
    padded = np.full((MARKER_PX + 2 * int(cell), MARKER_PX + 2 * int(cell)), WHITE_DN, dtype=np.float32)
    padded[int(cell) : int(cell) + MARKER_PX, int(cell) : int(cell) + MARKER_PX] = np.where(
        marker > 127, WHITE_DN, BLACK_DN
    )
    # Marker-image pixel centres are integers: the black square spans -0.5 .. MARKER_PX - 0.5 (+ margin).
    m0, m1 = cell - 0.5, cell + MARKER_PX - 0.5
    src = np.array([[m0, m0], [m1, m0], [m1, m1], [m0, m1]], dtype=np.float32)
    Hm = cv2.getPerspectiveTransform(src, corners_canvas.astype(np.float32))
    size = (canvas.shape[1], canvas.shape[0])
    warped = cv2.warpPerspective(padded, Hm, size, flags=cv2.INTER_LINEAR)
    mask = cv2.warpPerspective(np.ones_like(padded), Hm, size, flags=cv2.INTER_LINEAR)
    canvas[:] = canvas * (1.0 - mask) + warped * mask


_MARKERS: dict[int, np.ndarray] = {}


def _marker_image(tag_id: int) -> np.ndarray:
    import cv2

    if tag_id not in _MARKERS:
        d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
        _MARKERS[tag_id] = cv2.aruco.generateImageMarker(d, tag_id, MARKER_PX, borderBits=1)
    return _MARKERS[tag_id]


def render_all(sim: TagSimulation, seed: int) -> dict[tuple[str, int], np.ndarray]:
    """(camera id, frame) -> image, for every camera and frame."""
    rng = np.random.default_rng(seed + 7919)
    return {(cam.id, k): render_frame(sim, k, c, rng) for k in range(len(sim.t_s)) for c, cam in enumerate(sim.cameras)}


def detectable(sim: TagSimulation) -> list[tuple[int, int, int]]:
    """(frame, camera, tag) of the tags a detector can be expected to find: facing the camera
    within the simulation's ``max_view_deg`` and inside the image (the level-C bound uses these)."""
    seen = visible_tags(
        sim.R_world_body, sim.t_world_m, sim.T_body_tag, sim.config.tag_size_m, sim.cameras, sim.config.max_view_deg
    )
    return [(int(f), int(c), int(j)) for f, c, j in zip(*np.nonzero(seen), strict=True)]


def write_image_simulation(out: Path, config: TagSimConfig, seed: int) -> tuple[Path, Path]:
    """Simulate ``config`` (see ``image_config``), render, and write images.zip (scene.json and the
    PNGs) and truth.json (the bound over the tags facing each camera within ``max_view_deg``) into ``out``."""
    import cv2

    sim = simulate_tags(config, seed)
    out.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(out / "images.zip", "w", compression=zipfile.ZIP_STORED) as zf:
        zf.writestr("scene.json", json.dumps(sim.scene()))
        for (cam, k), img in render_all(sim, seed).items():
            ok, png = cv2.imencode(".png", img)
            assert ok
            zf.writestr(f"images/{cam}/{k:06d}.png", png.tobytes())
    truth = sim.truth(detectable(sim))
    truth["seed"] = seed
    (out / "truth.json").write_text(json.dumps(truth))
    return out / "images.zip", out / "truth.json"
