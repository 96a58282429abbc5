"""Frame assembly from timed clouds and range images, and every way such input can be unusable."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tumblescan import FrameCloud, Scanner, Scene, TimedCloud, simulate_frames
from tumblescan.errors import LimitExceededError, MalformedInputError, NonFiniteValueError, TimeOrderError
from tumblescan.linescan.errors import TooFewFramesError
from tumblescan.linescan.frames import assemble_frames, read_range_images

from ..conftest import motion_for

SCANNER = Scanner(lines=48, pixels=40)


@pytest.fixture(scope="module")
def dense() -> FrameCloud:
    return simulate_frames(motion_for(3), Scene(scanner=SCANNER, frames=6, noise=False), seed=3)


def plain(c: FrameCloud, **fields: np.ndarray) -> TimedCloud:
    return TimedCloud(c.xyz_m, c.t_s, dict(fields))


def test_frames_and_lines_from_indices_period_or_gaps_agree(dense: FrameCloud) -> None:
    truth_f, truth_l = dense.frame.astype(np.int64), dense.line.astype(np.int64)
    with_fields = assemble_frames(plain(dense, frame=dense.frame, line=dense.line))
    by_period = assemble_frames(plain(dense), frame_period_s=SCANNER.frame_period_s)
    by_gaps = assemble_frames(plain(dense))
    for frames in (with_fields, by_period, by_gaps):
        assert frames.n_frames == 6 and np.array_equal(frames.frame, truth_f)
    # Lines numbered by distinct time within the frame: the same order as the scanner's lines.
    for frames in (by_period, by_gaps):
        for f in range(6):
            sel = frames.frame == f
            ranks = np.unique(truth_l[sel], return_inverse=True)[1]
            assert np.array_equal(frames.line[sel], ranks)
    assert np.allclose(by_gaps.frame_times_s(), [np.mean(dense.t_s[dense.frame == f]) for f in range(6)])


def test_unusable_clouds_are_refused_with_the_reason(dense: FrameCloud) -> None:
    few = dense.frame < 3
    with pytest.raises(TooFewFramesError, match="3 frame"):
        assemble_frames(TimedCloud(dense.xyz_m[few], dense.t_s[few], {"frame": dense.frame[few]}))
    frame_time = np.floor(dense.t_s)  # every point stamped with its frame's start
    with pytest.raises(TimeOrderError, match="do not vary within frame 0"):
        assemble_frames(TimedCloud(dense.xyz_m, frame_time, {"frame": dense.frame}))
    continuous = TimedCloud(dense.xyz_m, np.linspace(0, 6, len(dense.t_s)))
    with pytest.raises(MalformedInputError, match="cannot tell the frames apart"):
        assemble_frames(continuous)
    with pytest.raises(MalformedInputError, match="non-negative integers"):
        assemble_frames(TimedCloud(dense.xyz_m, dense.t_s, {"frame": dense.frame.astype(float)}))


def range_image(c: FrameCloud, frames: int) -> dict[str, np.ndarray]:
    rng_m = np.zeros((frames, SCANNER.lines, SCANNER.pixels))
    rng_m[c.frame, c.line, c.pixel] = np.linalg.norm(c.xyz_m, axis=1)
    return {
        "range_m": rng_m,
        "t_s": SCANNER.line_times_s(frames),
        "azimuth_deg": np.degrees(SCANNER.azimuths_rad()),
        "elevation_deg": np.degrees(SCANNER.elevations_rad()),
    }


def test_range_images_become_the_same_points(dense: FrameCloud, tmp_path: Path) -> None:
    np.savez_compressed(tmp_path / "ri.npz", **range_image(dense, 6))  # type: ignore[arg-type]  # numpy stubs: **arrays could hit allow_pickle
    cloud = read_range_images(tmp_path / "ri.npz")
    order = np.lexsort((dense.pixel, dense.line, dense.frame))
    assert len(cloud) == len(dense.t_s)
    assert np.allclose(cloud.xyz_m, dense.xyz_m[order], atol=1e-9)
    assert np.array_equal(cloud.t_s, dense.t_s[order])
    assert np.array_equal(cloud.fields["line"], dense.line[order])
    assert assemble_frames(cloud).n_frames == 6


def test_bad_range_images_are_refused(dense: FrameCloud, tmp_path: Path) -> None:
    good = range_image(dense, 6)
    cases: list[tuple[dict[str, np.ndarray], type[Exception], str]] = [
        ({k: v for k, v in good.items() if k != "t_s"}, MalformedInputError, "lacks t_s"),
        ({**good, "extra": np.zeros(1)}, MalformedInputError, "unexpected array"),
        ({**good, "t_s": good["t_s"][:, :3]}, MalformedInputError, "t_s must be"),
        ({**good, "range_m": np.where(good["range_m"] > 0, np.nan, 0)}, NonFiniteValueError, "range_m"),
        ({**good, "range_m": -good["range_m"]}, MalformedInputError, "negative"),
        # A pickled array could run code when loaded: it is never unpickled.
        ({**good, "t_s": good["t_s"].astype(object)}, MalformedInputError, "allow_pickle=False"),
    ]
    for i, (arrays, error, message) in enumerate(cases):
        np.savez(tmp_path / f"bad{i}.npz", **arrays)  # type: ignore[arg-type]
        with pytest.raises(error, match=message):
            read_range_images(tmp_path / f"bad{i}.npz")
    (tmp_path / "text.npz").write_text("not a zip")
    with pytest.raises(MalformedInputError, match="not an NPZ"):
        read_range_images(tmp_path / "text.npz")


def test_a_zip_bomb_is_refused_before_it_is_expanded(tmp_path: Path) -> None:
    # 80 MB of zeros compress to a few hundred kB; the declared size gives it away.
    bomb = {
        "range_m": np.zeros((10, 1000, 1000)),
        "t_s": np.zeros((10, 1000)),
        "azimuth_deg": np.zeros(1000),
        "elevation_deg": np.zeros(1000),
    }
    np.savez_compressed(tmp_path / "bomb.npz", **bomb)  # type: ignore[arg-type]
    assert (tmp_path / "bomb.npz").stat().st_size < 1_000_000
    with pytest.raises(LimitExceededError, match="would expand to"):
        read_range_images(tmp_path / "bomb.npz", max_bytes=10_000_000)
