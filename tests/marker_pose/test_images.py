"""Level C (images): the detectors' corners against the exact projections of rendered tags (pixel
convention and corner order), poses near the truth, refusals naming the file, and the CLI."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from tumblescan.cli.marker_pose import app
from tumblescan.errors import InputError
from tumblescan.marker_pose.images_io import detect_tags, read_image_set
from tumblescan.marker_pose.options import ImagePoseOptions
from tumblescan.marker_pose.pipeline import run_images
from tumblescan.marker_pose.tag_camera import RigArrays, project, to_camera
from tumblescan.marker_pose.tag_detect import TagDetector
from tumblescan.marker_pose.tag_render import image_config, write_image_simulation
from tumblescan.marker_pose.tag_simulate import TagSimulation, simulate_tags


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, TagSimulation]:
    out = tmp_path_factory.mktemp("images")
    config = image_config(frames=3)
    archive, _ = write_image_simulation(out, config, 2)
    return archive, simulate_tags(config, 2)


def _exact(sim: TagSimulation, f: np.ndarray, c: np.ndarray, j: np.ndarray) -> np.ndarray:
    from tumblescan.marker_pose.tag_camera import tag_corners_body

    rig = RigArrays.of(sim.cameras)
    corners = tag_corners_body(sim.T_body_tag, sim.config.tag_size_m)[j]
    pw = np.einsum("nij,npj->npi", sim.R_world_body[f], corners) + sim.t_world_m[f][:, None]
    return np.asarray(project(to_camera(pw, c, rig), c, rig))


@pytest.mark.parametrize(("detector", "rms_max"), [("apriltag", 0.3), ("aruco", 1.0)])
def test_detected_corners_match_the_projections(
    scene: tuple[Path, TagSimulation], detector: str, rms_max: float
) -> None:
    archive, sim = scene
    data, info = detect_tags(read_image_set(archive), ImagePoseOptions(detector=detector))
    assert info.known_tags >= 20
    err = data.corners_px - _exact(sim, data.det_frame, data.det_cam, data.det_tag)
    # A wrong corner order or the 0.5 px centre offset would show here as errors of tens of px or a bias.
    assert np.sqrt(np.mean(err**2)) < rms_max
    assert np.all(np.abs(err.reshape(-1, 2).mean(axis=0)) < 0.1)


def test_images_give_poses_near_the_truth(scene: tuple[Path, TagSimulation]) -> None:
    archive, sim = scene
    result = run_images(archive)
    assert result.level == "C" and result.detection is not None
    assert [p.status for p in result.poses] == ["measured"] * 3
    for p in result.poses:
        assert p.T_world_body is not None and p.cov is not None
        assert np.linalg.norm(np.array(p.T_world_body.t_m) - sim.t_world_m[p.frame]) < 0.001
    assert any("estimated from the residuals" in w for w in result.warnings)


def _rewrite(src: Path, dst: Path, change: dict[str, bytes | None]) -> Path:
    with zipfile.ZipFile(src) as a, zipfile.ZipFile(dst, "w") as b:
        for name in a.namelist():
            if name in change:
                if change[name] is not None:
                    b.writestr(name, change[name])  # type: ignore[arg-type]
            else:
                b.writestr(name, a.read(name))
        for name, data in change.items():
            if name not in a.namelist() and data is not None:
                b.writestr(name, data)
    return dst


def test_bad_archives_are_refused_naming_the_member(scene: tuple[Path, TagSimulation], tmp_path: Path) -> None:
    archive, _ = scene
    small = cv2.imencode(".png", np.zeros((100, 120), np.uint8))[1].tobytes()
    cases: list[tuple[dict[str, bytes | None], str, str]] = [
        ({"images/cam1/000000.png": small}, "image_size_mismatch", "images/cam1/000000.png"),
        ({"images/cam9/000000.png": small}, "malformed_input", "images/cam9/000000.png"),
        ({"images/cam1/000042.png": small}, "malformed_input", "images/cam1/000042.png"),
        ({"../evil.png": small}, "malformed_input", "images"),
        ({"scene.json": None}, "malformed_input", "images"),
        ({"scene.json": b"[" * 100_000 + b"]" * 100_000}, "malformed_input", "scene.json"),
        ({"scene.json": b'{"cameras": '}, "malformed_input", "scene.json"),
    ]
    for i, (change, code, field) in enumerate(cases):
        bad = _rewrite(archive, tmp_path / f"bad{i}.zip", change)
        with pytest.raises(InputError) as err:
            image_set = read_image_set(bad)
            for key in image_set:
                image_set.read(key)
        assert (err.value.code, err.value.field) == (code, field), change.keys()


def test_cli_level_c_round_trip(tmp_path: Path) -> None:
    runner = CliRunner()
    r = runner.invoke(app, ["simulate", "--level", "C", "--out", str(tmp_path), "--seed", "3", "--frames", "3"])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["estimate", str(tmp_path / "images.zip"), "--json", "--detector", "aruco"])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["level"] == "C" and doc["detection"]["detector"] == "opencv aruco"
    r = runner.invoke(app, ["estimate", str(tmp_path / "images.zip"), "--method", "paper"])
    assert r.exit_code == 2 and "--method" in r.output


def test_16_bit_images_are_read_as_8_bit(scene: tuple[Path, TagSimulation], tmp_path: Path) -> None:
    archive, _ = scene
    name = "images/cam1/000000.png"
    with zipfile.ZipFile(archive) as zf:
        img8 = cv2.imdecode(np.frombuffer(zf.read(name), np.uint8), cv2.IMREAD_UNCHANGED)
    assert img8 is not None
    img16 = (img8.astype(np.uint16) * 257).astype(np.uint16)
    png16 = cv2.imencode(".png", img16)[1].tobytes()
    wide = read_image_set(_rewrite(archive, tmp_path / "w.zip", {name: png16}))
    key = next(k for k, v in wide.members.items() if v == name)
    detector = TagDetector("apriltag", "tag36h11")
    narrow = {d.id: d.corners_px for d in detector.detect(img8)}
    from_wide = {d.id: d.corners_px for d in detector.detect(wide.read(key))}
    assert narrow and set(from_wide) == set(narrow)  # the same tags, at the same corners
    assert all(np.max(np.abs(from_wide[i] - narrow[i])) < 0.05 for i in narrow)


def test_report_tells_what_the_detector_found(scene: tuple[Path, TagSimulation]) -> None:
    from tumblescan.marker_pose.report import build_report

    html = build_report(run_images(scene[0]), "images")
    assert "pupil-apriltags in 12 images" in html and "Residuals per tag" in html
