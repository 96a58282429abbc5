"""Motion from dense frames alone: a seeded simulate -> estimate -> compare round trip, every
input format, the bad inputs, the CLI and the service."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest

from tumblescan import (
    EstimateOptions,
    FrameCloud,
    FramesOptions,
    Motion,
    MotionResult,
    Scanner,
    Scene,
    SensorNoise,
    TimedCloud,
    assemble_frames,
    estimate_from_frames,
    random_motion,
    read_frames,
    read_ply,
    rectify,
    simulate_frames,
    write_ply,
)
from tumblescan.errors import InputError
from tumblescan.linescan.dense.data import prepare

from ...live import serve

SEED = 1
SCANNER = Scanner(lines=128, pixels=128)


@pytest.fixture(scope="module")
def simulated() -> tuple[Motion, FrameCloud]:
    motion = random_motion(np.random.default_rng(SEED))
    return motion, simulate_frames(motion, Scene(scanner=SCANNER), seed=SEED)


@pytest.fixture(scope="module")
def frames_ply(simulated: tuple[Motion, FrameCloud], tmp_path_factory: pytest.TempPathFactory) -> Path:
    _, sim = simulated
    path = tmp_path_factory.mktemp("dense") / "frames.ply"
    intensity = np.linspace(0, 1, len(sim.t_s)).astype(np.float32)
    write_ply(path, TimedCloud(sim.xyz_m, sim.t_s, {"frame": sim.frame, "line": sim.line, "intensity": intensity}))
    return path


@pytest.fixture(scope="module")
def estimated(frames_ply: Path) -> MotionResult:
    return estimate_from_frames(read_frames(frames_ply))


def _angle_deg(a: object, b: object) -> float:
    return float(np.degrees(np.arccos(np.clip(np.dot(a, b), -1.0, 1.0))))  # type: ignore[call-overload]


def test_round_trip_recovers_the_motion_within_its_uncertainty(
    simulated: tuple[Motion, FrameCloud], estimated: MotionResult
) -> None:
    truth = simulated[0].canonical().at_reference(estimated.reference_time_s)
    r, u = estimated, estimated.uncertainty
    assert r.model == "spin-precession"
    assert r.precession.axis is not None and u.precession_axis_deg is not None
    # Within 4 sigma, and the sigmas themselves small: dense data pin the motion down.
    assert _angle_deg(r.spin.axis, truth.spin_axis) < 4 * u.spin_axis_deg < 0.5
    assert _angle_deg(r.precession.axis, truth.precession_axis) < 4 * u.precession_axis_deg < 1.0
    assert abs(r.spin.rate_deg_s - np.degrees(truth.spin_rate_rad_s)) < 4 * u.spin_rate_deg_s < 0.1
    assert abs(r.precession.rate_deg_s - np.degrees(truth.precession_rate_rad_s)) < 4 * u.precession_rate_deg_s < 0.1
    assert np.linalg.norm(np.subtract(r.precession.center_m, truth.center_m)) < 0.05
    assert r.validation.passed and r.validation.test == "covariance"


def test_fit_describes_the_points_and_each_frame(estimated: MotionResult) -> None:
    fit = estimated.fit
    assert fit.source == "frames" and fit.tracks == 0 and fit.frames == 15
    assert fit.points_used is not None and 1000 < fit.points_used < fit.observations
    assert fit.frame_rms_m is not None and len(fit.frame_rms_m) == 15
    # Surfel centroids average the 2 cm range noise down to millimetres: no frame fits badly.
    rms = np.array(fit.frame_rms_m, dtype=float)
    assert np.all((rms > 1e-4) & (rms < 0.02)), rms
    assert rms.max() < 2 * np.median(rms)


def test_a_displaced_frame_stands_out_in_the_residuals(simulated: tuple[Motion, FrameCloud]) -> None:
    # Frame 7 moved 3 cm sideways (a timing or pointing fault): no motion explains it, and
    # its residuals say so.
    _, sim = simulated
    xyz = sim.xyz_m.copy()
    xyz[sim.frame == 7] += (0.03, 0.0, 0.0)
    frames = assemble_frames(TimedCloud(xyz, sim.t_s, {"frame": sim.frame, "line": sim.line}))
    rms = estimate_from_frames(frames).fit.frame_rms_m
    assert rms is not None
    values = np.array([np.nan if v is None else v for v in rms])
    assert int(np.nanargmax(values)) == 7, values


def test_spurious_returns_do_not_spoil_the_motion(simulated: tuple[Motion, FrameCloud]) -> None:
    # 10 % of the returns up to 3 m off along their ray: without leaving them out, no patch
    # passes for planar and the fit has nothing to work on.
    motion, sim = simulated
    rng = np.random.default_rng(7)
    bad = rng.random(len(sim.xyz_m)) < 0.10
    xyz = sim.xyz_m.copy()
    rho = np.linalg.norm(xyz[bad], axis=1, keepdims=True)
    xyz[bad] *= (rho + rng.uniform(-3.0, 3.0, (int(bad.sum()), 1))) / rho
    r = estimate_from_frames(assemble_frames(TimedCloud(xyz, sim.t_s, {"frame": sim.frame, "line": sim.line})))
    truth = motion.canonical().at_reference(r.reference_time_s)
    u = r.uncertainty
    assert _angle_deg(r.spin.axis, truth.spin_axis) < 4 * u.spin_axis_deg < 0.5
    assert abs(r.spin.rate_deg_s - np.degrees(truth.spin_rate_rad_s)) < 4 * u.spin_rate_deg_s < 0.1
    assert abs(r.precession.rate_deg_s - np.degrees(truth.precession_rate_rad_s)) < 4 * u.precession_rate_deg_s
    assert r.validation.passed
    left_out = [w for w in r.warnings if "spurious returns" in w]
    assert len(left_out) == 1 and int(left_out[0].split()[0]) > 0.6 * bad.sum()


def test_frames_without_a_planar_patch_in_common_are_refused(simulated: tuple[Motion, FrameCloud]) -> None:
    # Declared range noise of a micrometre: every patch of the 2 cm-noise frames is too thick
    # to pass for planar, so nothing can be matched. Refused with a reason, not reported with
    # zero uncertainty.
    _, sim = simulated
    frames = assemble_frames(TimedCloud(sim.xyz_m, sim.t_s, {"frame": sim.frame, "line": sim.line}))
    options = EstimateOptions(sensor=SensorNoise(range_sigma_m=1e-6, angle_sigma_arcsec=0.001))
    with pytest.raises(InputError, match="no planar patch of one frame could be matched"):
        estimate_from_frames(frames, options)


def test_a_scan_too_sparse_for_its_patches_is_refused_as_such() -> None:
    # 128 x 128 rays at 90 m fall about a cell apart on the box: no cell holds a patch, and the
    # refusal says so (not "one rigid target?" or "the declared noise?"). At 50 m it is dense enough.
    from bench.linescan.truth import dense_data

    from tumblescan.linescan.dense.estimate import _too_sparse

    scene = Scene(scanner=Scanner(lines=128, pixels=128))
    sim = simulate_frames(random_motion(np.random.default_rng(1), distance_m=90.0), scene, seed=1)
    frames = assemble_frames(TimedCloud(sim.xyz_m, sim.t_s, {"frame": sim.frame, "line": sim.line}))
    with pytest.raises(InputError, match=r"too sparse for this target at this range .* more lines and pixels"):
        estimate_from_frames(frames)
    near = simulate_frames(random_motion(np.random.default_rng(1), distance_m=50.0), scene, seed=1)
    assert _too_sparse(dense_data(near, float(near.t_s.min()), scene.scanner.noise.range_sigma_m)) is None


def test_rectified_cloud_matches_the_truth_within_a_centimetre(
    simulated: tuple[Motion, FrameCloud], estimated: MotionResult
) -> None:
    motion, sim = simulated
    T = estimated.reference_time_s
    got = rectify(sim.xyz_m, sim.t_s, estimated.motion(), to_time_s=T)
    want = rectify(sim.xyz_m, sim.t_s, motion, to_time_s=T)
    assert float(np.mean(np.linalg.norm(got - want, axis=1))) < 0.01


def test_point_npz_and_range_images_give_the_same_frames_as_ply(
    simulated: tuple[Motion, FrameCloud], frames_ply: Path, tmp_path: Path
) -> None:
    _, sim = simulated
    from_ply = read_frames(frames_ply)
    np.savez(tmp_path / "points.npz", xyz_m=sim.xyz_m, t_s=sim.t_s, frame=sim.frame, line=sim.line)
    from_points = read_frames(tmp_path / "points.npz")
    # Range images: frames x lines x pixels, 0 where a ray had no return.
    rng_m = np.zeros((15, SCANNER.lines, SCANNER.pixels))
    rng_m[sim.frame, sim.line, sim.pixel] = np.linalg.norm(sim.xyz_true_m, axis=1)
    times = SCANNER.line_times_s(15)
    np.savez(
        tmp_path / "ranges.npz",
        range_m=rng_m,
        t_s=times,
        azimuth_deg=np.degrees(SCANNER.azimuths_rad()),
        elevation_deg=np.degrees(SCANNER.elevations_rad()),
    )
    from_ranges = read_frames(tmp_path / "ranges.npz")
    for f in (from_points, from_ranges):
        assert f.n_frames == 15 and len(f.cloud) == len(sim.t_s)
        assert np.array_equal(np.bincount(f.frame), np.bincount(from_ply.frame))
    np.testing.assert_allclose(from_points.cloud.xyz_m, from_ply.cloud.xyz_m)
    # The range images hold the noise-free hits: the same points up to rounding, in scan order.
    order = np.lexsort((sim.pixel, sim.line, sim.frame))
    np.testing.assert_allclose(from_ranges.cloud.xyz_m, sim.xyz_true_m[order], atol=1e-9)


@pytest.mark.parametrize(
    ("arrays", "field", "words"),
    [
        ({"xyz_m": np.zeros((10, 2)), "t_s": np.zeros(10)}, "xyz_m", "(n, 3)"),
        ({"xyz_m": np.zeros((10, 3)), "t_s": np.zeros(9)}, "t_s", "one time per point"),
        ({"xyz_m": np.zeros((10, 3))}, "t_s", "lacks t_s"),
        ({"xyz_m": np.zeros((10, 3)), "t_s": np.zeros(10), "colour": np.zeros(10)}, "colour", "unexpected"),
        ({"xyz_m": np.zeros((10, 3)), "t_s": np.zeros(10), "frame": np.full(10, 0.5)}, "frame", "integer"),
    ],
)
def test_bad_point_npz_names_the_array(tmp_path: Path, arrays: dict[str, np.ndarray], field: str, words: str) -> None:
    np.savez(tmp_path / "bad.npz", **arrays)  # type: ignore[arg-type]
    with pytest.raises(InputError) as err:
        read_frames(tmp_path / "bad.npz")
    assert err.value.field == field and words in str(err.value)


def test_frames_given_one_time_each_are_refused(simulated: tuple[Motion, FrameCloud], tmp_path: Path) -> None:
    _, sim = simulated
    # A common mistake: every point stamped with its frame's time instead of its line's.
    write_ply(tmp_path / "snap.ply", TimedCloud(sim.xyz_m, sim.frame.astype(float), {"frame": sim.frame}))
    with pytest.raises(InputError, match="times do not vary within frame 0"):
        read_frames(tmp_path / "snap.ply")


def test_cli_estimates_frames_and_writes_the_rectified_cloud(frames_ply: Path, estimated: MotionResult) -> None:
    out = frames_ply.with_name("cli-rectified.ply")
    proc = subprocess.run(
        [sys.executable, "-m", "tumblescan", "estimate", str(frames_ply), "--json", "--rectified", str(out)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr
    result = MotionResult.model_validate_json(proc.stdout)
    # The same pipeline as in process; Open3D's threaded registration makes two runs differ by a few
    # 1e-5 deg/s under load, far inside the estimate's own uncertainty.
    wobble = 0.1 * estimated.uncertainty.spin_rate_deg_s
    assert result.spin.rate_deg_s == pytest.approx(estimated.spin.rate_deg_s, abs=wobble)
    original, rectified = read_ply(frames_ply), read_ply(out)
    assert len(rectified) == len(original)
    assert set(rectified.fields) == {"frame", "line", "intensity"}
    np.testing.assert_array_equal(rectified.fields["intensity"], original.fields["intensity"])


def test_cli_noise_overrides_reach_the_frames_estimator(frames_ply: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from typer.testing import CliRunner

    from tumblescan.cli import app
    from tumblescan.linescan.dense import estimate as frames_estimator

    seen: list[FramesOptions] = []

    class SeenError(Exception):
        pass

    def spy(frames: object, options: FramesOptions, **_: object) -> MotionResult:
        seen.append(options)
        raise SeenError

    monkeypatch.setattr(frames_estimator, "estimate_from_frames", spy)
    run = CliRunner().invoke(app, ["estimate", str(frames_ply), "--range-sigma-m", "0.05", "--seed", "3"])
    assert isinstance(run.exception, SeenError)
    assert seen[0].sensor == SensorNoise(range_sigma_m=0.05, angle_sigma_arcsec=SensorNoise().angle_sigma_arcsec)
    assert seen[0].seed == 3


@pytest.fixture(scope="module")
def http(tmp_path_factory: pytest.TempPathFactory) -> Iterator[httpx.Client]:
    with serve(tmp_path_factory.mktemp("dense-svc") / "data") as url, httpx.Client(base_url=url, timeout=60) as c:
        yield c


def test_upload_of_frames_returns_the_motion_and_the_rectified_cloud(
    http: httpx.Client, frames_ply: Path, estimated: MotionResult, tmp_path: Path
) -> None:
    with open(frames_ply, "rb") as fh:
        r = http.post("/v1/jobs/upload", files={"file": ("frames.ply", fh)})
    assert r.status_code == 202, r.text
    stages = set()
    job = r.json()
    while job["status"] not in ("succeeded", "failed", "cancelled"):
        stages.add(job["stage"])
        job = http.get(f"/v1/jobs/{job['id']}", params={"wait": 1}).json()
    assert job["status"] == "succeeded", job
    # Some of the long stages are seen while polling once a second.
    assert stages & {"registering", "initializing", "refining", "validating"}, stages
    # Workers run Open3D single-threaded, whose RANSAC draws differ from the multithreaded
    # library run: the same motion within the estimate's own uncertainty, not bit for bit.
    got = MotionResult.model_validate(job["result"])
    assert abs(got.spin.rate_deg_s - estimated.spin.rate_deg_s) < 3 * estimated.uncertainty.spin_rate_deg_s
    assert got.fit.source == "frames" and got.validation.passed
    cloud = http.get(job["artifacts"]["cloud"])
    (tmp_path / "out.ply").write_bytes(cloud.content)
    assert len(read_ply(tmp_path / "out.ply")) == len(read_ply(frames_ply))
    page = http.get(f"/v1/jobs/{job['id']}/report")
    assert page.status_code == 200 and "Surfel-to-plane residuals per frame" in page.text


def test_bad_frame_uploads_are_422_naming_the_field(http: httpx.Client, frames_ply: Path, tmp_path: Path) -> None:
    three = tmp_path / "three.ply"
    frame = np.repeat(np.arange(3), 10).astype(np.int32)
    t_s = frame.astype(float) + np.tile(np.arange(10) * 0.01, 3)
    write_ply(three, TimedCloud(np.ones((30, 3)), t_s, {"frame": frame}))
    r = http.post("/v1/jobs/upload", files={"file": ("three.ply", three.read_bytes())})
    assert r.status_code == 422 and r.json()["detail"]["code"] == "too_few_frames", r.text
    assert "at least 4" in r.json()["detail"]["message"]
    with open(frames_ply, "rb") as fh:
        body = fh.read()
    r = http.post("/v1/jobs/upload", files={"file": ("f.ply", body), "cloud": ("c.ply", body)})
    assert r.status_code == 422 and r.json()["detail"]["field"] == "cloud"
    r = http.post("/v1/jobs/upload", files={"file": ("f.npz", b"PK\x03\x04 not really")})
    assert r.status_code == 422 and r.json()["detail"]["field"] == "file"
    r = http.post(
        "/v1/jobs/upload", files={"file": ("f.ply", body)}, data={"options": json.dumps({"frame_period_s": -1})}
    )
    assert r.status_code == 422 and "frame_period_s" in r.text
    # A frame period beside the points' own frame indices would be ignored: refused instead.
    r = http.post(
        "/v1/jobs/upload", files={"file": ("f.ply", body)}, data={"options": json.dumps({"frame_period_s": 1.0})}
    )
    assert r.status_code == 422 and "frame_period_s" in r.text and "'frame' property" in r.text, r.text
    # Dense-fit settings are checked at the boundary too, naming the nested field.
    r = http.post(
        "/v1/jobs/upload", files={"file": ("f.ply", body)}, data={"options": json.dumps({"dense": {"sources": 5}})}
    )
    assert r.status_code == 422 and "sources" in r.text, r.text


def test_dense_data_keeps_the_first_frames_consistent(simulated: tuple[Motion, FrameCloud]) -> None:
    _, sim = simulated
    data = prepare(sim.xyz_m, sim.t_s - sim.t_s.min(), sim.frame.astype(np.int64), surfel_m=0.2)
    first = data.first_frames(5)
    assert first.n_frames == 5 and np.array_equal(first.xyz_m, sim.xyz_m[sim.frame < 5])
    # Every point still belongs to a surfel of its own frame.
    assert np.array_equal(first.cell_frame[first.cell], first.frame)
    assert len(first.interior) == len(first.cell_frame) == first.cell.max() + 1


def test_surfel_cells_do_not_depend_on_the_range_noise() -> None:
    # A wall seen face-on at 50 m, twice: without noise and with 5 cm range noise. Cells are cut in
    # the sensor's view, so each point lands in the same surfel either way (a 3D voxel grid would
    # move points across the faces it shares with the wall).
    rng = np.random.default_rng(0)
    az, el = np.meshgrid(np.linspace(-0.05, 0.05, 200), np.linspace(-0.05, 0.05, 200))
    d = np.stack([np.sin(az) * np.cos(el), np.sin(el), np.cos(az) * np.cos(el)], axis=-1).reshape(-1, 3)
    clean = d * (50.0 / d[:, 2])[:, None]
    noisy = clean + d * rng.normal(0, 0.05, len(d))[:, None]
    t = np.repeat(np.arange(200) * 1e-3, 200)
    frame = np.zeros(len(d), np.int64)
    a = prepare(clean, t, frame, surfel_m=0.3)
    b = prepare(noisy, t, frame, surfel_m=0.3)
    assert np.array_equal(a.cell, b.cell)


def test_pure_spin_from_frames_is_reported_spin_only() -> None:
    # A target spinning about one fixed axis, seen as dense frames: the Wald test finds no
    # precession, and the spin-only refit recovers the axis and rate within their uncertainty.
    motion = Motion.from_degrees(spin_axis=(0.3, 0.8, 0.5), spin_rate_deg_s=20.0, center_m=(0.0, 0.0, 50.0))
    sim = simulate_frames(motion, Scene(scanner=SCANNER), seed=4)
    r = estimate_from_frames(assemble_frames(TimedCloud(sim.xyz_m, sim.t_s, {"frame": sim.frame, "line": sim.line})))
    assert r.model == "spin-only", r.warnings
    assert any("no significant precession" in w for w in r.warnings)
    truth = motion.canonical().at_reference(r.reference_time_s)
    assert _angle_deg(r.spin.axis, truth.spin_axis) < 4 * r.uncertainty.spin_axis_deg < 0.5
    assert abs(r.spin.rate_deg_s - 20.0) < 4 * r.uncertainty.spin_rate_deg_s < 0.1
    assert r.validation.passed


def test_nearly_parallel_axes_are_reported_as_such() -> None:
    # Spin and precession 3 deg apart turn the target nearly as one rotation: the frames fix
    # it, not its split between spin and precession. The result says so, with the spin-only
    # answer (about the common axis at the summed rate), instead of a confident split.
    l_s = np.array([0.3, 0.8, 0.5]) / np.linalg.norm([0.3, 0.8, 0.5])
    across = np.cross(l_s, (1.0, 0.0, 0.0)) / np.linalg.norm(np.cross(l_s, (1.0, 0.0, 0.0)))
    l_p = np.cos(np.radians(3.0)) * l_s + np.sin(np.radians(3.0)) * across
    motion = Motion.from_degrees(
        spin_axis=l_s, spin_rate_deg_s=20.0, precession_axis=l_p, precession_rate_deg_s=8.0, center_m=(0.0, 0.0, 50.0)
    )
    sim = simulate_frames(motion, Scene(scanner=SCANNER), seed=4)
    r = estimate_from_frames(assemble_frames(TimedCloud(sim.xyz_m, sim.t_s, {"frame": sim.frame, "line": sim.line})))
    said = [w for w in r.warnings if w.startswith("near-degenerate motion") and "unreliable" in w]
    assert len(said) == 1, r.warnings
    rate = float(said[0].split(" at ")[1].split(" deg/s")[0])
    assert abs(rate - 28.0) < 0.5  # the spin-only model turns at about 20 + 8 cos 3 deg/s
