"""Every refusal in the digest's list, with its code and the field it names."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tumblescan.errors import InputError
from tumblescan.imaging.image_io import write_image
from tumblescan.panel_axis.meta import parse_meta
from tumblescan.panel_axis.pipeline import load_input, run
from tumblescan.panel_axis.simulate import BROKEN_META, simulate_view, write_view


def _refusal(meta: Path) -> InputError:
    with pytest.raises(InputError) as exc:
        run(load_input(meta))
    return exc.value


# The width is checked against the image (below); every other broken field is caught in meta.json.
META_ONLY = [k for k, (field, _) in enumerate(BROKEN_META) if field != "camera.width_px"]


@pytest.mark.parametrize("seed", META_ONLY)
def test_each_broken_meta_is_invalid_input_naming_its_field(seed: int) -> None:
    meta = _broken(seed)
    field = BROKEN_META[seed][0]
    with pytest.raises(InputError) as exc:
        parse_meta(json.dumps(meta, allow_nan=True))
    assert exc.value.code == "invalid_input"
    assert exc.value.field == field, str(exc.value)
    assert field.split(".")[-1] in str(exc.value)


def test_the_simulator_writes_broken_meta_with_the_expected_error(tmp_path: Path) -> None:
    write_view(tmp_path, simulate_view(1, case="broken-meta", width_px=640, height_px=480))
    truth = json.loads((tmp_path / "truth.json").read_text())
    with pytest.raises(InputError) as exc:
        load_input(tmp_path / "meta.json")
    assert exc.value.code == truth["expected_error"]["code"] and exc.value.field == truth["expected_error"]["field"]


def _broken(seed: int) -> dict[str, object]:
    """A broken meta without rendering (the simulator's breaker on a valid meta)."""
    from tumblescan.panel_axis import simulate as sim

    meta = json.loads(json.dumps(_valid_meta()))
    sim._break(meta, BROKEN_META[seed][0], np.eye(3))
    return meta  # type: ignore[no-any-return,unused-ignore]


def _valid_meta() -> dict[str, object]:
    return {
        "schema": "tumblescan.panel_axis.input/1",
        "image": "image.png",
        "camera": {"model": "pinhole", "width_px": 640, "height_px": 480, "fx_px": 1500.0, "fy_px": 1500.0,
                   "cx_px": 319.5, "cy_px": 239.5, "skew": 0.0, "distortion": None},
        "pointing": {"frame": "station_enu", "azimuth_deg": 288.0, "elevation_deg": 52.0, "roll_deg": 0.0},
        "station": {"lat_deg": 34.27, "lon_deg": 108.95, "height_m": 400.0},
        "prior": {"range_m": 70.0, "panel_length_m": 5.5, "panel_width_m": 2.0, "wings": 2},
    }  # fmt: skip


def test_a_width_that_is_not_the_images_is_refused(tmp_path: Path) -> None:
    meta = _valid_meta()
    meta["camera"]["width_px"] = 642  # type: ignore[index]
    (tmp_path / "meta.json").write_text(json.dumps(meta))
    write_image(tmp_path / "image.png", np.zeros((480, 640), np.uint8))
    err = _refusal(tmp_path / "meta.json")
    assert err.code == "invalid_input" and err.field == "camera.width_px" and "640x480" in str(err)


@pytest.mark.parametrize(
    ("image", "message"),
    [
        (np.zeros((480, 640, 4), np.uint8), "4 channels"),
        (np.zeros((480, 640), np.float32), "float32"),
        (np.zeros((60, 640), np.uint8), "64"),
    ],
)
def test_refused_images(tmp_path: Path, image: np.ndarray, message: str) -> None:
    meta = _valid_meta()
    h, w = image.shape[:2]
    meta["camera"].update(width_px=w, height_px=h, cx_px=(w - 1) / 2, cy_px=(h - 1) / 2)  # type: ignore[attr-defined]
    (tmp_path / "meta.json").write_text(json.dumps(meta))
    import tifffile

    tifffile.imwrite(tmp_path / "image.tif", image)
    meta["image"] = "image.tif"
    (tmp_path / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(InputError) as exc:
        load_input(tmp_path / "meta.json")
    assert exc.value.code == "invalid_input" and message in str(exc.value)


def test_nan_and_unknown_fields_are_refused_by_name() -> None:
    text = json.dumps(_valid_meta()).replace('"fx_px": 1500.0', '"fx_px": NaN')
    with pytest.raises(InputError, match=r"camera\.fx_px: not a finite number"):
        parse_meta(text)
    meta = _valid_meta()
    meta["prior"]["mass_kg"] = 3.0  # type: ignore[index]
    with pytest.raises(InputError) as exc:
        parse_meta(json.dumps(meta))
    assert exc.value.field == "prior.mass_kg"


def test_an_unreadable_image(tmp_path: Path) -> None:
    (tmp_path / "meta.json").write_text(json.dumps(_valid_meta()))
    (tmp_path / "image.png").write_bytes(b"GIF89a not a png")
    err = _refusal(tmp_path / "meta.json")
    assert err.code == "unreadable_image" and err.field == "image"


def test_a_blank_sky_has_no_target(tmp_path: Path) -> None:
    write_view(tmp_path, simulate_view(1, case="blank", width_px=640, height_px=480))
    err = _refusal(tmp_path / "meta.json")
    assert err.code == "no_target" and err.field == "image"


def test_a_scalloped_blob_has_too_few_edges(tmp_path: Path) -> None:
    import cv2

    img = np.full((480, 640), 6, np.uint8)
    for k in range(12):  # a chain of discs: elongated, with no straight edge of 30 px
        cv2.circle(img, (200 + 20 * k, 240 + 8 * k), 14, 120, -1, cv2.LINE_AA)
    write_image(tmp_path / "image.png", img)
    (tmp_path / "meta.json").write_text(json.dumps(_valid_meta()))
    err = _refusal(tmp_path / "meta.json")
    assert err.code == "too_few_edges"


@pytest.mark.parametrize(("case", "seed"), [("edge-on", 0), ("edge-on", 1), ("end-on", 0), ("end-on", 2)])
def test_edge_on_and_end_on_views_are_degenerate(tmp_path: Path, case: str, seed: int) -> None:
    write_view(tmp_path, simulate_view(seed, case=case, width_px=640, height_px=480))  # type: ignore[arg-type]
    err = _refusal(tmp_path / "meta.json")
    assert err.code == "degenerate_view" and err.field == "image"


def test_a_shortest_edge_longer_than_any_image_is_an_invalid_option() -> None:
    # It was accepted, and the job failed with a 300-digit length in its too_few_edges message.
    from pydantic import ValidationError

    from tumblescan.panel_axis.options import EstimateOptions

    assert EstimateOptions(min_line_px=1_000_000).min_line_px == 1_000_000
    with pytest.raises(ValidationError, match="min_line_px"):
        EstimateOptions(min_line_px=1e308)


@pytest.mark.parametrize(
    ("path", "value"),
    [
        ("camera.fx_px", 1e308),
        ("camera.skew", 1e12),
        ("camera.distortion", [1e300, 0.0, 0.0, 0.0, 0.0]),
        ("pointing.azimuth_deg", 1e300),
        ("pointing.roll_deg", -1e300),
        ("station.height_m", 1e300),
        ("prior.range_m", 1e300),
        ("prior.panel_length_m", 1e300),
        ("prior.panel_width_m", 1e300),
    ],
)
def test_absurdly_large_numbers_are_refused_naming_their_field(path: str, value: object) -> None:
    # Each was accepted: the job then failed far from the cause (too_few_edges) or "succeeded".
    meta = _valid_meta()
    block, key = path.split(".")
    meta[block][key] = value  # type: ignore[index]
    with pytest.raises(InputError) as exc:
        parse_meta(json.dumps(meta))
    assert exc.value.code == "invalid_input" and exc.value.field is not None and exc.value.field.startswith(path)


@pytest.mark.parametrize(
    ("path", "value", "words"),
    [
        ("camera.fx_px", True, "not true"),  # was a focal length of 1 px: tilt 87.48 ± 0.015 deg, confidently wrong
        ("camera.fx_px", "2400", 'not "2400"'),
        ("camera.fy_px", False, "not false"),
        ("camera.cx_px", "319.5", 'not "319.5"'),
        ("camera.cy_px", True, "not true"),
        ("camera.skew", "0", 'not "0"'),
        ("camera.distortion.4", True, "not true"),
        ("camera.width_px", True, "an integer is expected"),
        ("camera.height_px", "480", 'not "480"'),
        ("pointing.azimuth_deg", "288", 'not "288"'),
        ("pointing.elevation_deg", True, "not true"),
        ("pointing.roll_deg", "0", 'not "0"'),
        ("station.lat_deg", "34.27", 'not "34.27"'),
        ("station.lon_deg", True, "not true"),
        ("station.height_m", "400", 'not "400"'),
        ("prior.range_m", "70", 'not "70"'),
        ("prior.panel_length_m", True, "not true"),
        ("prior.panel_width_m", "2", 'not "2"'),
        ("prior.wings", True, "an integer is expected"),
    ],
)
def test_a_bool_or_a_string_is_not_a_number(path: str, value: object, words: str) -> None:
    meta = _valid_meta()
    block, key, *index = path.split(".")
    if index:
        meta[block][key] = [0.0] * 5  # type: ignore[index]
        meta[block][key][int(index[0])] = value  # type: ignore[index]
    else:
        meta[block][key] = value  # type: ignore[index]
    with pytest.raises(InputError) as exc:
        parse_meta(json.dumps(meta))
    assert exc.value.code == "invalid_input" and exc.value.field == path, str(exc.value)
    assert str(exc.value).startswith(f"{path}: ") and words in str(exc.value)


def test_a_bool_in_the_rotation_is_not_a_number() -> None:
    meta = _valid_meta()
    meta["pointing"] = {"frame": "ecef", "R_cam_from_ref": [[1, 0, 0], [0, 1, 0], [0, 0, True]]}
    with pytest.raises(InputError) as exc:
        parse_meta(json.dumps(meta))
    assert exc.value.field == "pointing.R_cam_from_ref.2.2" and "not true" in str(exc.value)


def test_integers_written_as_whole_floats_and_plain_numbers_still_pass() -> None:
    meta = _valid_meta()
    meta["camera"].update(width_px=640.0, fx_px=1500, cx_px=319)  # type: ignore[attr-defined]
    meta["prior"]["wings"] = 2.0  # type: ignore[index]
    parsed = parse_meta(json.dumps(meta))
    assert parsed.camera.width_px == 640 and parsed.camera.fx_px == 1500.0 and parsed.prior.wings == 2  # type: ignore[union-attr]


@pytest.mark.parametrize("option", ["min_line_px", "weak_snr"])
@pytest.mark.parametrize("value", [float("inf"), float("-inf"), float("nan")])
def test_every_float_option_refuses_nan_and_infinity(option: str, value: float) -> None:
    # {"weak_snr": Infinity} was accepted and forced every view to weak perspective; a NaN
    # min_line_px was called out of range.
    from pydantic import ValidationError

    from tumblescan.panel_axis.options import EstimateOptions

    with pytest.raises(ValidationError) as exc:
        EstimateOptions.model_validate({option: value})
    err = exc.value.errors()[0]
    assert err["loc"] == (option,) and err["msg"] == "Input should be a finite number"


def test_options_that_act_on_the_weak_perspective_test_are_refused_with_the_paper_method() -> None:
    from pydantic import ValidationError

    from tumblescan.panel_axis.options import EstimateOptions

    assert EstimateOptions(method="paper", require_axis=False).method == "paper"
    # Every option at its default, as a client sending all of them would: nothing to ignore.
    assert EstimateOptions.model_validate({**EstimateOptions().model_dump(), "method": "paper"}).method == "paper"
    for extra in ({"require_axis": True}, {"weak_snr": 5.0}):
        with pytest.raises(ValidationError) as exc:
            EstimateOptions.model_validate({"method": "paper", **extra})
        err = exc.value.errors()[0]
        assert err["loc"] == (next(iter(extra)),) and "does not apply to method 'paper'" in err["msg"]
