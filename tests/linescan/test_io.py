"""Tracks JSON/CSV and PLY clouds: round trips and every bad-input case."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from tumblescan import (
    TimedCloud,
    read_ply,
    read_tracks,
    tracks_from_csv,
    tracks_from_json,
    tracks_to_json,
    write_ply,
    write_tracks,
)
from tumblescan.errors import (
    MalformedInputError,
    MissingTimeError,
    NonFiniteValueError,
    TimeOrderError,
    UnknownFieldError,
)
from tumblescan.linescan.errors import (
    DuplicateObservationError,
    SingleObservationTrackError,
    TooFewFramesError,
    TooFewTracksError,
)
from tumblescan.linescan.tracks import infer_frames

from ..conftest import tracks_for


@pytest.mark.parametrize("suffix", [".json", ".csv"])
def test_tracks_round_trip_exactly(tmp_path: Path, suffix: str) -> None:
    _, tracks = tracks_for(0)
    path = tmp_path / f"tracks{suffix}"
    write_tracks(path, tracks)
    back = read_tracks(path)
    assert back.track_ids == tracks.track_ids
    assert np.array_equal(back.t_s, tracks.t_s) and np.array_equal(back.xyz_m, tracks.xyz_m)
    assert np.array_equal(back.frame, tracks.frame)


def test_frames_are_inferred_from_times_when_not_given() -> None:
    _, tracks = tracks_for(1)
    doc = tracks_to_json(tracks)
    for o in doc["observations"]:
        del o["frame"]
    inferred = tracks_from_json(doc)
    assert np.array_equal(inferred.frame, tracks.frame)
    assert np.array_equal(infer_frames(tracks.track, tracks.t_s), tracks.frame)


def test_sensor_block_is_read() -> None:
    _, tracks = tracks_for(1)
    doc = tracks_to_json(tracks)
    doc["sensor"] = {"range_sigma_m": 0.05, "angle_sigma_arcsec": 10}
    assert tracks_from_json(doc).sensor is not None
    assert tracks_from_json(doc).sensor.range_sigma_m == 0.05  # type: ignore[union-attr]


def _doc(**changes: object) -> dict:
    _, tracks = tracks_for(2)
    doc = tracks_to_json(tracks)
    doc.update(changes)
    return doc


def test_bad_tracks_get_specific_errors() -> None:
    base = _doc()
    obs = base["observations"]

    def with_obs(i: int, **kv: object) -> dict:
        d = json.loads(json.dumps(base))
        d["observations"][i].update(kv)
        return d

    with pytest.raises(NonFiniteValueError, match=r"observations\[3\]\.t"):
        tracks_from_json(json.dumps(base).replace(json.dumps(obs[3]["t"]), "NaN", 1))
    with pytest.raises(NonFiniteValueError, match=r"observations\[4\]\.xyz"):
        tracks_from_json(with_obs(4, xyz=[1.0, float("inf"), 2.0]))
    with pytest.raises(UnknownFieldError, match="colour"):
        tracks_from_json(with_obs(0, colour="red"))
    with pytest.raises(UnknownFieldError, match="extra"):
        tracks_from_json({**base, "extra": 1})
    with pytest.raises(UnknownFieldError, match=r"sensor\.noise"):
        tracks_from_json({**base, "sensor": {"noise": 1}})
    with pytest.raises(MalformedInputError, match=r"observations\[2\]\.xyz must be a list of 3"):
        tracks_from_json(with_obs(2, xyz=[1, 2]))
    with pytest.raises(MalformedInputError, match="missing t"):
        d = json.loads(json.dumps(base))
        del d["observations"][1]["t"]
        tracks_from_json(d)
    with pytest.raises(MalformedInputError, match="not valid JSON"):
        tracks_from_json("{observations: [")
    dup = json.loads(json.dumps(base))
    dup["observations"].append(dict(dup["observations"][0]))
    for o in dup["observations"]:
        o.pop("frame")
    with pytest.raises(DuplicateObservationError, match="two observations at t="):
        tracks_from_json(dup)


def test_structural_problems_get_specific_errors() -> None:
    t = np.arange(8, dtype=float)
    xyz = np.random.default_rng(0).normal(size=(8, 3)) + np.array([0, 0, 50])
    with pytest.raises(SingleObservationTrackError, match="'d'"):
        tracks_from_json(_obs(["a", "a", "b", "b", "c", "c", "d", "a"], t, xyz))
    with pytest.raises(TooFewTracksError, match="2 track"):
        tracks_from_json(_obs(["a", "b"] * 4, t, xyz))
    with pytest.raises(TooFewFramesError, match="3 frame"):
        tracks_from_json(
            _obs(
                ["a", "b", "c"] * 3, np.repeat([0.0, 1.0, 2.0], 3) + np.tile([0, 0.1, 0.2], 3), np.tile(xyz[:1], (9, 1))
            )
        )
    frames = [0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3]
    times = [0.0, 0.1, 0.2, 1.0, 1.1, 1.2, 2.0, 2.1, 2.2, 3.0, 3.1, 1.5]
    with pytest.raises(TimeOrderError, match=r"frame 2 has an observation at t=2\.2"):
        tracks_from_json(_obs(["a", "b", "c"] * 4, times, np.tile(xyz[:1], (12, 1)), frames))


def _obs(names: list[str], t: object, xyz: object, frames: list[int] | None = None) -> dict:
    t_l, xyz_l = np.asarray(t).tolist(), np.asarray(xyz).tolist()
    obs = [{"track": n, "t": ti, "xyz": p} for n, ti, p in zip(names, t_l, xyz_l, strict=True)]
    if frames is not None:
        for o, f in zip(obs, frames, strict=True):
            o["frame"] = f
    return {"observations": obs}


def test_csv_errors_name_the_line() -> None:
    with pytest.raises(MalformedInputError, match="header"):
        tracks_from_csv("id,t,x,y,z\n")
    with pytest.raises(MalformedInputError, match="line 3"):
        tracks_from_csv("track,t,x,y,z\nc1,0,1,2,3\nc1,zero,1,2,3\n")
    with pytest.raises(NonFiniteValueError):
        tracks_from_csv("track,t,x,y,z\nc1,0,1,2,nan\n")


def _cloud(n: int = 1000) -> TimedCloud:
    rng = np.random.default_rng(0)
    return TimedCloud(
        xyz_m=rng.normal(size=(n, 3)),
        t_s=np.sort(rng.uniform(0, 15, n)),
        fields={
            "frame": (np.arange(n) // 100).astype(np.int32),
            "line": (np.arange(n) % 100).astype(np.int32),
            "intensity": rng.random(n).astype(np.float32),
        },
    )


def test_ply_round_trips_bit_exact_with_extra_fields(tmp_path: Path) -> None:
    cloud = _cloud()
    write_ply(tmp_path / "c.ply", cloud)
    back = read_ply(tmp_path / "c.ply")
    assert np.array_equal(back.xyz_m, cloud.xyz_m) and np.array_equal(back.t_s, cloud.t_s)
    for name, a in cloud.fields.items():
        assert back.fields[name].dtype == a.dtype and np.array_equal(back.fields[name], a)


@pytest.mark.parametrize("name", ["timestamp", "time"])
def test_ply_time_property_may_be_called_timestamp_or_time(tmp_path: Path, name: str) -> None:
    cloud = _cloud(10)
    write_ply(tmp_path / "c.ply", cloud, time_name=name)
    assert np.array_equal(read_ply(tmp_path / "c.ply").t_s, cloud.t_s)


def test_ply_written_by_open3d_is_read(tmp_path: Path) -> None:
    import open3d as o3d

    cloud = _cloud(50)
    pcd = o3d.t.geometry.PointCloud(o3d.core.Tensor(cloud.xyz_m))  # type: ignore[call-overload]
    pcd.point["timestamp"] = o3d.core.Tensor(cloud.t_s[:, None])  # type: ignore[call-overload]
    assert o3d.t.io.write_point_cloud(str(tmp_path / "o.ply"), pcd)  # type: ignore[arg-type]
    back = read_ply(tmp_path / "o.ply")
    assert np.array_equal(back.t_s, cloud.t_s) and np.allclose(back.xyz_m, cloud.xyz_m)


def test_big_endian_and_ascii_ply_are_read(tmp_path: Path) -> None:
    xyz = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    t = np.array([0.5, 0.75])
    be = np.zeros(2, dtype=[("x", ">f8"), ("y", ">f8"), ("z", ">f8"), ("t", ">f8")])
    for i, a in enumerate("xyz"):
        be[a] = xyz[:, i]
    be["t"] = t
    head = (
        "ply\nformat binary_big_endian 1.0\nelement vertex 2\n"
        + "".join(f"property double {a}\n" for a in "xyzt")
        + "end_header\n"
    )
    (tmp_path / "be.ply").write_bytes(head.encode() + be.tobytes())
    assert np.array_equal(read_ply(tmp_path / "be.ply").xyz_m, xyz)
    ascii_head = head.replace("binary_big_endian", "ascii")
    (tmp_path / "a.ply").write_text(ascii_head + "1 2 3 0.5\n4 5 6 0.75\n")
    assert np.array_equal(read_ply(tmp_path / "a.ply").t_s, t)
    # No vertices, no body: an empty cloud, as from a binary PLY, without numpy's warning.
    (tmp_path / "empty.ply").write_text(ascii_head.replace("vertex 2", "vertex 0"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        empty = read_ply(tmp_path / "empty.ply")
    assert len(empty) == 0 and empty.xyz_m.shape == (0, 3)


def test_bad_ply_files_get_specific_errors(tmp_path: Path) -> None:
    cloud = _cloud(100)
    write_ply(tmp_path / "ok.ply", cloud)
    raw = (tmp_path / "ok.ply").read_bytes()
    (tmp_path / "lying.ply").write_bytes(raw.replace(b"element vertex 100", b"element vertex 900"))
    with pytest.raises(MalformedInputError, match="declares 900 vertices but the file holds only 100"):
        read_ply(tmp_path / "lying.ply")
    (tmp_path / "trunc.ply").write_bytes(raw[: len(raw) // 2])
    with pytest.raises(MalformedInputError, match="truncated"):
        read_ply(tmp_path / "trunc.ply")
    (tmp_path / "notply.ply").write_bytes(b"hello")
    with pytest.raises(MalformedInputError, match="not a PLY"):
        read_ply(tmp_path / "notply.ply")
    (tmp_path / "nohdr.ply").write_bytes(b"ply\nformat ascii 1.0\n")
    with pytest.raises(MalformedInputError, match="end_header"):
        read_ply(tmp_path / "nohdr.ply")
    write_ply(tmp_path / "notime.ply", TimedCloud(cloud.xyz_m, cloud.t_s), time_name="stamp")
    with pytest.raises(MissingTimeError, match="no per-point time property"):
        read_ply(tmp_path / "notime.ply")
    nan = TimedCloud(cloud.xyz_m.copy(), cloud.t_s.copy())
    nan.t_s[7] = np.nan
    write_ply(tmp_path / "nan.ply", nan)
    with pytest.raises(NonFiniteValueError, match="vertex 7"):
        read_ply(tmp_path / "nan.ply")
    order = TimedCloud(cloud.xyz_m, cloud.t_s[::-1].copy(), dict(cloud.fields))
    write_ply(tmp_path / "order.ply", order)
    with pytest.raises(TimeOrderError, match="within frame 0"):
        read_ply(tmp_path / "order.ply")


GOOD_MOTION = {
    "spin_axis": [0.0, 0.0, 1.0],
    "spin_rate_deg_s": 10.0,
    "precession_axis": [0.0, 1.0, 0.0],
    "precession_rate_deg_s": 2.0,
    "center_m": [0.0, 0.0, 50.0],
    "reference_time_s": 0.0,
}


@pytest.mark.parametrize(
    ("content", "field", "says"),
    [
        (b"\xff\xfe not json", "truth", "not valid JSON"),
        (b"[1, 2]", "truth", "no 'motion'"),
        (json.dumps({"motion": {**GOOD_MOTION, "spin_axis": [0, 1]}}).encode(), "truth.motion.spin_axis", "3 finite"),
        (
            json.dumps({"motion": {**GOOD_MOTION, "precession_axis": [0, 0, 0]}}).encode(),
            "truth.motion.precession_axis",
            "zero vector",
        ),
        (
            json.dumps({"motion": {k: v for k, v in GOOD_MOTION.items() if k != "precession_rate_deg_s"}}).encode(),
            "truth.motion.precession_rate_deg_s",
            "finite number",
        ),
    ],
)
def test_a_truth_file_that_is_not_one_is_refused_naming_what_is_wrong(
    tmp_path: Path, content: bytes, field: str, says: str
) -> None:
    from tumblescan.linescan.truth import load_truth

    path = tmp_path / "truth.json"
    path.write_bytes(content)
    with pytest.raises(MalformedInputError) as err:
        load_truth(path)
    assert err.value.field == field and says in str(err.value)
    assert "Error" not in str(err.value)  # no Python exception names in what a user reads


def test_a_truth_file_round_trips(tmp_path: Path) -> None:
    from tumblescan.linescan.truth import load_truth

    path = tmp_path / "truth.json"
    path.write_text(json.dumps({"motion": GOOD_MOTION}))
    motion = load_truth(path)
    assert np.isclose(np.degrees(motion.spin_rate_rad_s), 10.0) and np.allclose(motion.center_m, [0, 0, 50])


def test_tracks_nested_too_deeply_are_refused_naming_tracks() -> None:
    from tumblescan.linescan.tracks_io import tracks_from_json

    with pytest.raises(MalformedInputError, match="nests too deeply") as err:
        tracks_from_json("[" * 100_000 + "]" * 100_000)
    assert err.value.field == "tracks"
