"""Every code of the error table, with its field: invalid_input and unreadable_image at the door,
no_target, undersampled, too_few_features and not_converged from the estimate."""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from tumblescan.errors import InputError
from tumblescan.imaging.image_io import write_image
from tumblescan.spin_rate import estimate as estimate_mod
from tumblescan.spin_rate.errors import NoTargetError, NotConvergedError, TooFewFeaturesError, UndersampledError
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
