"""The estimator against the simulator's truth: near range (clean and noisy), ground (weak
perspective), and the paper's pipeline."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tumblescan.errors import InputError
from tumblescan.panel_axis.frames import pitch_yaw_deg
from tumblescan.panel_axis.options import EstimateOptions
from tumblescan.panel_axis.pipeline import load_input, run


def _angle_deg(a: list[float], b: list[float]) -> float:
    return float(np.degrees(np.arccos(min(1.0, abs(float(np.dot(a, b)))))))


@pytest.mark.parametrize("name", ["near_clean", "near_noisy"])
def test_near_range_axis_is_within_the_bound_and_its_sigma(name: str, request: pytest.FixtureRequest) -> None:
    d: Path = request.getfixturevalue(name)
    truth = json.loads((d / "truth.json").read_text())
    r = run(load_input(d / "meta.json"))
    assert r.observability.regime == "perspective" and not r.ambiguous
    assert r.axis is not None and r.axis.sigma_deg is not None
    err = _angle_deg(r.axis.camera, truth["axis_camera"])
    assert err <= max(0.5, 3 * truth["sigma_crlb_deg"])
    assert err <= 5 * r.axis.sigma_deg
    # The station and ECEF vectors are the same line in other frames; pitch/yaw follow eq. 1.
    assert _angle_deg(r.axis.station_enu, truth["axis_station_enu"]) == pytest.approx(err, abs=1e-6)  # type: ignore[arg-type]
    assert _angle_deg(r.axis.ecef, truth["axis_ecef"]) == pytest.approx(err, abs=1e-6)  # type: ignore[arg-type]
    assert r.axis.station_enu[1] >= 0 and r.axis.ecef[1] >= 0  # type: ignore[index]
    pitch, yaw = pitch_yaw_deg(np.array(r.axis.station_enu))
    assert (r.axis.pitch_deg, r.axis.yaw_deg) == (pytest.approx(pitch), pytest.approx(yaw))
    assert r.panel.orthogonality_deg is not None and r.panel.orthogonality_deg < 1.0


def test_the_papers_pipeline_returns_a_direction_without_sigma(near_clean: Path) -> None:
    truth = json.loads((near_clean / "truth.json").read_text())
    r = run(load_input(near_clean / "meta.json"), EstimateOptions(method="paper"))
    assert r.method == "paper" and r.axis is not None and r.axis.sigma_deg is None
    assert _angle_deg(r.axis.camera, truth["axis_camera"]) < 20.0


def test_weak_perspective_is_ambiguous_and_one_candidate_is_the_truth(ground: Path) -> None:
    truth = json.loads((ground / "truth.json").read_text())
    r = run(load_input(ground / "meta.json"))
    assert r.observability.regime == "weak_perspective" and r.ambiguous
    assert "weak_perspective" in r.warnings
    assert [c.kind for c in r.candidates] == ["primary", "mirror"]
    errors = [_angle_deg(c.camera, truth["axis_camera"]) for c in r.candidates]
    assert min(errors) < 5.0
    # Never the line of sight: the answer the planes' intersection would give.
    los = np.array(truth["t_cam_m"]) / np.linalg.norm(truth["t_cam_m"])
    assert all(_angle_deg(c.camera, los.tolist()) > 10.0 for c in r.candidates)


def test_weak_perspective_without_a_prior_gives_the_image_angle_only(ground: Path, tmp_path: Path) -> None:
    meta = json.loads((ground / "meta.json").read_text())
    del meta["prior"]
    meta["image"] = str((ground / "image.png").resolve())
    (tmp_path / "meta.json").write_text(json.dumps(meta))
    truth = json.loads((ground / "truth.json").read_text())
    r = run(load_input(tmp_path / "meta.json"))
    assert r.axis is None and r.ambiguous and r.candidates == []
    # The true axis's image direction at the target.
    K = np.array(
        [
            [meta["camera"]["fx_px"], 0, meta["camera"]["cx_px"]],
            [0, meta["camera"]["fy_px"], meta["camera"]["cy_px"]],
            [0, 0, 1],
        ]
    )
    t = np.array(truth["t_cam_m"])
    a, b = K @ t, K @ (t + 5.0 * np.array(truth["axis_camera"]))
    du = b[:2] / b[2] - a[:2] / a[2]
    true_angle = np.degrees(np.arctan2(du[1], du[0])) % 180.0
    diff = abs(r.image_angle_deg - true_angle) % 180.0
    assert min(diff, 180 - diff) < 0.5
    with pytest.raises(InputError) as exc:
        run(load_input(tmp_path / "meta.json"), EstimateOptions(require_axis=True))
    assert exc.value.code == "depth_unobservable" and exc.value.field == "prior"


def test_a_pointing_matrix_in_ecef_gives_the_same_axis_as_azimuth_and_elevation(
    near_clean: Path, tmp_path: Path
) -> None:
    from tumblescan.panel_axis.frames import R_cam_from_enu, R_ecef_from_enu

    meta = json.loads((near_clean / "meta.json").read_text())
    p, st = meta["pointing"], meta["station"]
    R_cam_ecef = R_cam_from_enu(p["azimuth_deg"], p["elevation_deg"]) @ R_ecef_from_enu(st["lat_deg"], st["lon_deg"]).T
    meta["pointing"] = {"frame": "ecef", "R_cam_from_ref": R_cam_ecef.tolist()}
    meta["image"] = str((near_clean / "image.png").resolve())
    (tmp_path / "meta.json").write_text(json.dumps(meta))
    a = run(load_input(near_clean / "meta.json")).axis
    b = run(load_input(tmp_path / "meta.json")).axis
    assert a is not None and b is not None
    assert np.allclose(a.station_enu, b.station_enu, atol=1e-9) and np.allclose(a.ecef, b.ecef, atol=1e-9)  # type: ignore[arg-type]
    assert b.pitch_deg == pytest.approx(a.pitch_deg) and b.sigma_yaw_deg == pytest.approx(a.sigma_yaw_deg)


def test_a_16_bit_tiff_gives_the_same_answer_as_the_png(ground: Path, tmp_path: Path) -> None:
    import tifffile

    from tumblescan.imaging.image_io import read_image

    img = read_image(ground / "image.png")
    assert img.dtype == np.uint16
    tifffile.imwrite(tmp_path / "image.tif", img)
    meta = json.loads((ground / "meta.json").read_text())
    meta["image"] = "image.tif"
    (tmp_path / "meta.json").write_text(json.dumps(meta))
    a, b = run(load_input(ground / "meta.json")), run(load_input(tmp_path / "meta.json"))
    assert a.image_angle_deg == pytest.approx(b.image_angle_deg, abs=1e-12)
    assert [c.camera for c in a.candidates] == [c.camera for c in b.candidates]
