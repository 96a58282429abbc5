"""Every code of the error table, with its field: invalid_input and unreadable_image at the door,
no_target, undersampled, too_few_features and not_converged from the estimate."""

from __future__ import annotations

import io
import itertools
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest
from pydantic import BaseModel, ValidationError

from tumblescan.errors import InputError
from tumblescan.imaging.image_io import write_image
from tumblescan.spin_rate import estimate as estimate_mod
from tumblescan.spin_rate.errors import NoTargetError, NotConvergedError, TooFewFeaturesError, UndersampledError
from tumblescan.spin_rate.meta import CameraMeta, FrameMeta, MetaOptions, PriorMeta, SpinInput, parse_meta
from tumblescan.spin_rate.options import EstimateOptions
from tumblescan.spin_rate.pipeline import load_input, run, unpack_zip
from tumblescan.spin_rate.simulate import BROKEN_META, break_meta


def _with_meta(src: Path, dst: Path, meta: dict[str, object]) -> Path:
    dst.mkdir(parents=True, exist_ok=True)
    (dst / "frames").mkdir(exist_ok=True)
    for f in (src / "frames").iterdir():
        (dst / "frames" / f.name).write_bytes(f.read_bytes())
    (dst / "meta.json").write_text(json.dumps(meta))
    return dst / "meta.json"


@pytest.mark.parametrize("how", list(BROKEN_META))
def test_broken_meta_is_invalid_input_naming_the_field(los_seq: Path, tmp_path: Path, how: str) -> None:
    meta = json.loads((los_seq / "meta.json").read_text())
    break_meta(meta, how)
    with pytest.raises(InputError) as exc:
        load_input(_with_meta(los_seq, tmp_path, meta))
    assert exc.value.code == "invalid_input"
    assert exc.value.field == BROKEN_META[how], str(exc.value)


@pytest.mark.parametrize(
    ("path", "value", "field"),
    [
        ("prior.min_rate_deg_s", 1e6, "prior.min_rate_deg_s"),
        ("prior.max_rate_deg_s", -1.0, "prior.max_rate_deg_s"),
        ("camera.distortion", [0.1, 0.0], "camera.distortion"),
        ("camera.cx_px", "nan", "camera.cx_px"),
    ],
)
def test_more_invalid_fields(los_seq: Path, tmp_path: Path, path: str, value: object, field: str) -> None:
    meta = json.loads((los_seq / "meta.json").read_text())
    a, b = path.split(".")
    meta[a][b] = float("nan") if value == "nan" else value
    with pytest.raises(InputError) as exc:
        load_input(_with_meta(los_seq, tmp_path, meta))
    assert exc.value.code == "invalid_input" and exc.value.field == field


def test_float_and_four_channel_frames_are_invalid(los_seq: Path, tmp_path: Path) -> None:
    import tifffile

    meta = json.loads((los_seq / "meta.json").read_text())
    mp = _with_meta(los_seq, tmp_path, meta)
    name = meta["frames"][2]["file"]
    tifffile.imwrite(tmp_path / name, np.zeros((256, 256), np.float32))
    with pytest.raises(InputError) as exc:
        load_input(mp)
    assert exc.value.code == "invalid_input" and exc.value.field == "frames.2.file"


def test_a_truncated_png_is_unreadable_image(corrupt_seq: Path) -> None:
    with pytest.raises(InputError) as exc:
        load_input(corrupt_seq / "meta.json")
    assert exc.value.code == "unreadable_image"
    assert exc.value.field is not None and exc.value.field.startswith("frames.")


def test_blank_frames_are_no_target(blank_seq: Path) -> None:
    with pytest.raises(NoTargetError) as exc:
        run(load_input(blank_seq / "meta.json"))
    assert exc.value.code == "no_target" and exc.value.field == "frames"


def test_an_aliasing_prior_is_undersampled(los_seq: Path, tmp_path: Path) -> None:
    meta = json.loads((los_seq / "meta.json").read_text())
    dt = np.median(np.diff([f["t_s"] for f in meta["frames"]]))
    meta["prior"]["max_rate_deg_s"] = float(200.0 / dt)
    with pytest.raises(UndersampledError) as exc:
        run(load_input(_with_meta(los_seq, tmp_path, meta)))
    assert exc.value.code == "undersampled" and exc.value.field == "prior.max_rate_deg_s"


def test_a_blob_without_edges_is_too_few_features(los_seq: Path, tmp_path: Path) -> None:
    meta = json.loads((los_seq / "meta.json").read_text())
    mp = _with_meta(los_seq, tmp_path, meta)
    yy, xx = np.mgrid[0:256, 0:256]
    for k, f in enumerate(meta["frames"]):
        blob = 200 * np.exp(-((xx - 128 - k) ** 2 + (yy - 120) ** 2) / (2 * 25.0**2))
        write_image(tmp_path / f["file"], np.clip(blob + 3, 0, 255).astype(np.uint8))
    with pytest.raises(TooFewFeaturesError) as exc:
        run(load_input(mp))
    assert exc.value.code == "too_few_features" and exc.value.field == "frames"


def test_a_fit_without_finite_sigma_is_not_converged(los_seq: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    real = estimate_mod.fit_rigid

    def nan_sigma(*a: object, **k: object) -> object:
        import dataclasses

        return dataclasses.replace(real(*a, **k), sigma_omega_rad_s=float("nan"))  # type: ignore[arg-type]

    from tumblescan.spin_rate import association, search

    for mod in (estimate_mod, association, search):  # every module that fits
        monkeypatch.setattr(mod, "fit_rigid", nan_sigma)
    with pytest.raises(NotConvergedError) as exc:
        run(load_input(los_seq / "meta.json"))
    assert exc.value.code == "not_converged"


def _zip(members: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    return buf.getvalue()


def test_zip_path_tricks_and_bombs_are_refused(tmp_path: Path) -> None:
    (tmp_path / "evil.zip").write_bytes(_zip({"../escape.txt": b"x", "meta.json": b"{}"}))
    with pytest.raises(InputError) as exc:
        unpack_zip(tmp_path / "evil.zip", tmp_path / "out1")
    assert exc.value.field == "archive" and "unsafe" in str(exc.value)
    assert not (tmp_path / "escape.txt").exists()
    (tmp_path / "bomb.zip").write_bytes(_zip({"meta.json": b"{}", "frames/a.png": b"\0" * 50_000_000}))
    with pytest.raises(InputError) as exc:
        unpack_zip(tmp_path / "bomb.zip", tmp_path / "out2")
    assert exc.value.code == "limit_exceeded"
    (tmp_path / "junk.zip").write_bytes(b"PK\x03\x04 not really")
    with pytest.raises(InputError) as exc:
        unpack_zip(tmp_path / "junk.zip", tmp_path / "out3")
    assert exc.value.field == "archive"


def _meta_text(src: Path, path: str, value: object) -> str:
    """``src``'s meta.json with the field at dotted ``path`` (``frames.0.t_s``) set to ``value``."""
    meta = json.loads((src / "meta.json").read_text())
    *parents, last = path.split(".")
    node = meta
    for key in parents:
        node = node[int(key)] if isinstance(node, list) else node[key]
    node[int(last) if isinstance(node, list) else last] = value
    return json.dumps(meta)


@pytest.mark.parametrize(
    ("path", "value", "expected"),
    [
        ("camera.fx_px", True, "a JSON number"),  # was a focal length of 1 px: a wrong rate, no refusal
        ("camera.fx_px", "2400", "a JSON number"),
        ("frames.1.t_s", "1.7", "a JSON number"),
        ("camera.width_px", 256.5, "a JSON integer"),
        ("camera.distortion", [0.0, 0.0, 0.0, 0.0, False], "a JSON number"),
        ("prior.max_rate_deg_s", "90", "a JSON number"),
        ("options.return_tracks", "yes", "a JSON bool (true or false)"),
        ("options.return_tracks", 1, "a JSON bool (true or false)"),
        ("epoch_utc", 5, "a JSON string"),
    ],
)
def test_a_value_of_the_wrong_json_type_is_refused_naming_the_field(
    los_seq: Path, path: str, value: object, expected: str
) -> None:
    with pytest.raises(InputError) as exc:
        parse_meta(_meta_text(los_seq, path, value))
    assert exc.value.code == "invalid_input" and str(exc.value.field).startswith(path), str(exc.value)
    shown = json.dumps(value[-1] if isinstance(value, list) else value)  # what came, as JSON
    assert f"{expected} is expected, not the " in str(exc.value) and str(exc.value).endswith(shown)


@pytest.mark.parametrize(
    ("path", "value", "says"),
    [
        ("camera.cx_px", 1e6, "outside the image"),  # was accepted: 2.09 ± 96 deg/s for 14.59
        ("camera.cy_px", -3.0, "outside the image"),
        ("exposure_s", 1e9, "over twice the frames' median interval"),
        ("epoch_utc", "yesterday", "ISO-8601"),
        ("epoch_utc", "2024-05-01", "ISO-8601"),  # a date without a time
        ("epoch_utc", "2024-05-01T12:00:00+02:00", "not in UTC"),
    ],
)
def test_a_value_out_of_its_range_is_refused_naming_the_field(
    los_seq: Path, path: str, value: object, says: str
) -> None:
    with pytest.raises(InputError) as exc:
        parse_meta(_meta_text(los_seq, path, value))
    assert exc.value.field == path and says in str(exc.value), str(exc.value)


@pytest.mark.parametrize("epoch", ["2024-05-01T12:00:00Z", "2024-05-01T12:00:00.25+00:00", "2024-05-01 12:00:00", None])
def test_a_utc_epoch_is_accepted(los_seq: Path, epoch: str | None) -> None:
    assert parse_meta(_meta_text(los_seq, "epoch_utc", epoch)).epoch_utc == epoch


def test_a_whole_image_size_written_as_a_float_is_accepted(los_seq: Path) -> None:
    # As panel-axis takes it (one camera block for both): some writers put 512.0 for 512.
    meta = json.loads((los_seq / "meta.json").read_text())
    width = meta["camera"]["width_px"]
    assert parse_meta(_meta_text(los_seq, "camera.width_px", float(width))).camera.width_px == width


def test_an_exposure_up_to_the_frame_interval_is_accepted(los_seq: Path) -> None:
    meta = json.loads((los_seq / "meta.json").read_text())
    gap = min(b["t_s"] - a["t_s"] for a, b in itertools.pairwise(meta["frames"]))
    assert parse_meta(_meta_text(los_seq, "exposure_s", gap)).exposure_s == gap
    # A whole-frame exposure a rounding over the interval (0.0333 s at 30 fps, times to the ms).
    assert parse_meta(_meta_text(los_seq, "exposure_s", 1.01 * gap)).exposure_s == 1.01 * gap


@pytest.mark.parametrize("model", [EstimateOptions, SpinInput, FrameMeta, CameraMeta, PriorMeta, MetaOptions])
def test_every_input_and_option_model_refuses_nan_and_unknown_fields(model: type[BaseModel]) -> None:
    # Any float field, now or later, must refuse NaN and Infinity ("finite number").
    assert model.model_config.get("allow_inf_nan") is False and model.model_config.get("extra") == "forbid"


@pytest.mark.parametrize("model", [SpinInput, FrameMeta, CameraMeta, PriorMeta, MetaOptions])
def test_every_input_model_is_strict(model: type[BaseModel]) -> None:
    # Lax models took true for 1 and "yes" for true, in fields not listed in the tests above too.
    assert model.model_config.get("strict") is True


@pytest.mark.parametrize(
    ("options", "field"),
    [({"return_tracks": "yes"}, "return_tracks"), ({"return_tracks": 1}, "return_tracks"), ({"method": 1}, "method")],
)
def test_options_of_the_wrong_json_type_are_refused(options: dict[str, object], field: str) -> None:
    with pytest.raises(ValidationError) as exc:
        EstimateOptions.model_validate(options)
    assert exc.value.errors()[0]["loc"] == (field,)


def test_a_frame_that_is_a_directory_says_so(los_seq: Path, tmp_path: Path) -> None:
    # It said "is not in the input".
    meta = json.loads((los_seq / "meta.json").read_text())
    mp = _with_meta(los_seq, tmp_path, meta)
    name = meta["frames"][2]["file"]
    (tmp_path / name).unlink()
    (tmp_path / name).mkdir()
    with pytest.raises(InputError) as exc:
        load_input(mp)
    assert exc.value.field == "frames.2.file" and "is a directory" in str(exc.value)
