"""The options of marker-pose-graph: finite values within bounds the graph can solve, and options
that another option makes meaningless refused by name (never ignored)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from pydantic import BaseModel, ValidationError

from tumblescan.marker_pose.estimate import estimate_poses
from tumblescan.marker_pose.evaluate import evaluate
from tumblescan.marker_pose.markers_io import markers_from_json
from tumblescan.marker_pose.options import (
    MAX_PSD,
    MIN_PSD,
    ImagePoseOptions,
    MarkerPoseOptions,
    TagPoseOptions,
)
from tumblescan.marker_pose.simulate import SimConfig, simulate
from tumblescan.marker_pose.tag_estimate import estimate_tag_poses
from tumblescan.marker_pose.tag_simulate import TagSimConfig, simulate_tags
from tumblescan.marker_pose.tags_io import tags_from_json

CV = {"motion_prior": "constant_velocity"}
FLOATS: list[tuple[type[BaseModel], str, dict[str, Any]]] = [
    (MarkerPoseOptions, "angular_accel_psd", CV),
    (MarkerPoseOptions, "accel_psd", CV),
    (MarkerPoseOptions, "robust_k", {"robust": "huber"}),
    (MarkerPoseOptions, "outlier_sigma", {}),
    (MarkerPoseOptions, "point_sigma_m", {}),
    (TagPoseOptions, "angular_accel_psd", CV),
    (TagPoseOptions, "accel_psd", CV),
    (TagPoseOptions, "outlier_sigma", {}),
    (TagPoseOptions, "pixel_sigma_px", {}),
    (ImagePoseOptions, "quad_decimate", {}),
]


def _refused(model: type[BaseModel], options: dict[str, Any]) -> tuple[str, str]:
    with pytest.raises(ValidationError) as err:
        model.model_validate(options)
    first = err.value.errors(include_url=False)[0]
    return ".".join(str(p) for p in first["loc"]), first["msg"]


@pytest.mark.parametrize("value", [float("nan"), float("inf"), -float("inf")])
@pytest.mark.parametrize(("model", "name", "with_"), FLOATS, ids=[f"{m.__name__}.{n}" for m, n, _ in FLOATS])
def test_non_finite_options_are_refused_by_name(
    model: type[BaseModel], name: str, with_: dict[str, Any], value: float
) -> None:
    assert _refused(model, with_ | {name: value})[0] == name


@pytest.mark.parametrize("name", ["angular_accel_psd", "accel_psd"])
@pytest.mark.parametrize("value", [1e-300, 0.1 * MIN_PSD, 10 * MAX_PSD, 1e300])
def test_psds_beyond_their_bounds_are_refused_by_name(name: str, value: float) -> None:
    # 1e-300 and an infinite PSD once reached GTSAM and failed the job ("indeterminate linear system").
    for model in (MarkerPoseOptions, TagPoseOptions, ImagePoseOptions):
        assert _refused(model, CV | {name: value})[0] == name


EXTREMES = [(MIN_PSD, MIN_PSD), (MAX_PSD, MAX_PSD), (MIN_PSD, MAX_PSD), (MAX_PSD, MIN_PSD)]


@pytest.fixture(scope="module")
def tumbling_box() -> tuple[Any, dict[str, Any]]:
    sim = simulate(SimConfig(target="box", motion="tumble", frames=150), 1)
    return markers_from_json(sim.document()), sim.truth()


@pytest.mark.parametrize(("q_rot", "q_trans"), EXTREMES)
def test_psd_bounds_run_at_level_a(tumbling_box: tuple[Any, dict[str, Any]], q_rot: float, q_trans: float) -> None:
    # A stiff rotation beside a loose translation (1e-6 and 1e4) made GTSAM's Cholesky marginals
    # fail on this run ("indeterminate linear system"); the QR fallback solves it.
    data, truth = tumbling_box
    options = MarkerPoseOptions(motion_prior="constant_velocity", angular_accel_psd=q_rot, accel_psd=q_trans)
    result = estimate_poses(data, options)
    assert result.graph.model_extra is not None
    assert result.graph.model_extra["psd"] == {"angular_rad2_s3": q_rot, "linear_m2_s3": q_trans}
    ev = evaluate(result, truth)
    assert ev["coverage"] >= 0.9 and np.isfinite(ev["nees_over_6"])
    assert all(p.cov is not None and np.all(np.isfinite(p.cov)) for p in result.poses if p.status == "measured")


@pytest.mark.parametrize(("q_rot", "q_trans"), EXTREMES)
def test_psd_bounds_run_at_level_b_at_1_khz(q_rot: float, q_trans: float) -> None:
    # Precise tag poses 1 ms apart: the stiffest motion factors a deployment meets.
    sim = simulate_tags(TagSimConfig(frames=100, frame_rate_hz=1000.0), 0)
    options = TagPoseOptions(motion_prior="constant_velocity", angular_accel_psd=q_rot, accel_psd=q_trans)
    result = estimate_tag_poses(tags_from_json(sim.document()), options)
    ev = evaluate(result, sim.truth())
    assert ev["coverage"] >= 0.98 and np.isfinite(ev["nees_over_6"])


@pytest.mark.parametrize("name", ["angular_accel_psd", "accel_psd", "max_bridge_frames"])
def test_motion_tunings_without_the_prior_are_refused(name: str) -> None:
    value = 20 if name == "max_bridge_frames" else 1.0
    for model in (MarkerPoseOptions, TagPoseOptions, ImagePoseOptions):
        where, msg = _refused(model, {name: value})
        assert where == name and "constant_velocity" in msg
    # The default, sent explicitly, changes nothing and is taken.
    assert MarkerPoseOptions(max_bridge_frames=10).max_bridge_frames == 10


def test_paper_method_takes_no_motion_prior_nor_robust_kernel() -> None:
    where, msg = _refused(MarkerPoseOptions, {"method": "paper", "motion_prior": "constant_velocity"})
    assert where == "motion_prior" and "method 'paper'" in msg
    assert _refused(MarkerPoseOptions, {"method": "paper", "robust": "huber"})[0] == "robust"
    assert _refused(MarkerPoseOptions, {"robust_k": 2.0})[0] == "robust_k"
    assert MarkerPoseOptions(method="paper").motion_prior == "none"


def test_decimation_is_refused_with_aruco() -> None:
    assert _refused(ImagePoseOptions, {"detector": "aruco", "quad_decimate": 2.0})[0] == "quad_decimate"
    assert ImagePoseOptions(detector="apriltag", quad_decimate=2.0).quad_decimate == 2.0
