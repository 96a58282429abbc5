"""Level B (tag corners from calibrated cameras): estimates against seeded simulations' truth and
the tag bound, the projection Jacobian against finite differences, refusals naming their field,
and the CLI."""

from __future__ import annotations

import copy
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from tumblescan.cli.marker_pose import app
from tumblescan.errors import InputError
from tumblescan.marker_pose.evaluate import evaluate
from tumblescan.marker_pose.geometry import exp_so3
from tumblescan.marker_pose.options import TagPoseOptions
from tumblescan.marker_pose.tag_camera import RigArrays, project, projection_jacobian, to_camera
from tumblescan.marker_pose.tag_estimate import estimate_tag_poses
from tumblescan.marker_pose.tag_simulate import TagSimConfig, paper_rig, simulate_tags
from tumblescan.marker_pose.tags_io import tags_from_json

from .edits import set_at


@pytest.mark.parametrize(("motion", "seed"), [("paper", 0), ("tumble", 1)])
def test_tag_poses_reach_the_tag_bound(motion: str, seed: int) -> None:
    sim = simulate_tags(TagSimConfig(motion=motion, frames=150), seed)
    result = estimate_tag_poses(tags_from_json(sim.document()))
    ev = evaluate(result, sim.truth())
    assert result.level == "B"
    assert ev["ratio"] <= 1.3
    assert ev["coverage"] >= 0.98
    assert ev["worst_mahalanobis"] <= 8
    assert 0.25 <= ev["nees_over_6"] <= 4
    assert ev["rot_3sigma_deg"] < 0.3 and ev["pos_3sigma_mm"] < 1.0  # the digest's 0.26 deg / 0.7 mm class


def test_gross_corner_errors_are_rejected() -> None:
    sim = simulate_tags(TagSimConfig(frames=150, outlier_fraction=0.02), 2)
    result = estimate_tag_poses(tags_from_json(sim.document()))
    bad = {
        (f, f"{sim.cameras[c].id}/tag{sim.tag_ids[j]}")
        for f, c, j, o in zip(sim.det_frame, sim.det_cam, sim.det_tag, sim.outlier, strict=True)
        if o
    }
    rejected = {(r.frame, r.track) for r in result.residuals.rejected}
    assert len(bad) >= 10
    assert len(bad & rejected) >= 0.9 * len(bad)  # the gross errors (3-10 px) are caught
    assert len(rejected - bad) <= 0.01 * len(sim.det_frame)  # and hardly any good detection
    assert evaluate(result, sim.truth())["ratio"] <= 1.3


def test_constant_velocity_prior_smooths_below_the_per_frame_bound() -> None:
    sim = simulate_tags(TagSimConfig(frames=150), 3)
    result = estimate_tag_poses(tags_from_json(sim.document()), TagPoseOptions(motion_prior="constant_velocity"))
    ev = evaluate(result, sim.truth())
    assert ev["ratio"] < 0.8
    assert 0.25 <= ev["nees_over_6"] <= 4
    assert result.graph.factors["motion"] > 100


def test_projection_jacobian_matches_finite_differences() -> None:
    rig = RigArrays.of(paper_rig(distortion=(-0.1, 0.02, 0.001, -0.002, 0.003)))
    rng = np.random.default_rng(0)
    R = exp_so3(rng.normal(size=3))[None]
    t = np.array([[0.2, -0.1, 1.3]])
    p = rng.uniform(-0.2, 0.2, (1, 4, 3))
    cam = np.array([2])
    uv, J = projection_jacobian(R, t, p, cam, rig)
    for i in range(6):
        d = np.zeros(6)
        d[i] = 1e-7
        Rp, tp = exp_so3(d[:3]) @ R[0], t[0] + d[3:]
        uv_p = project(to_camera(np.einsum("ij,npj->npi", Rp, p) + tp, cam, rig), cam, rig)
        assert np.allclose((uv_p - uv) / 1e-7, J[..., i], rtol=1e-4, atol=1e-2)


BASE = simulate_tags(TagSimConfig(frames=20), 0).document()


CASES: list[tuple[str, Callable[[dict[str, Any]], None], str, str]] = [
    ("units", set_at(["units", "length"], "mm"), "unsupported_units", "units.length"),
    (
        "NaN",
        set_at(["detections", 2, "corners_px", 1, 0], float("nan")),
        "non_finite_value",
        "detections[2].corners_px[1][0]",
    ),
    ("K lower", set_at(["cameras", 1, "K", 1, 0], 5.0), "invalid_camera", "cameras[1].K"),
    ("K negative", set_at(["cameras", 0, "K", 0, 0], -100.0), "invalid_camera", "cameras[0].K"),
    ("not rigid", set_at(["cameras", 2, "T_world_cam", 0, 0], 2.0), "invalid_camera", "cameras[2].T_world_cam"),
    (
        "corners 3",
        set_at(["detections", 4, "corners_px"], [[1, 2], [3, 4], [5, 6]]),
        "invalid_corners",
        "detections[4].corners_px",
    ),
    (
        "corner out",
        set_at(["detections", 4, "corners_px", 0], [5000.0, 10.0]),
        "invalid_corners",
        "detections[4].corners_px",
    ),
    ("family", set_at(["tags", "family"], "tag99h1"), "unknown_family", "tags.family"),
    ("size", set_at(["tags", "size_m"], 0.0), "malformed_input", "tags.size_m"),
    ("sigma", set_at(["cameras", 0, "pixel_sigma"], 0.0), "noise_out_of_range", "cameras[0].pixel_sigma"),
    ("camera", set_at(["detections", 1, "camera"], "cam9"), "malformed_input", "detections[1].camera"),
    (
        "duplicate",
        lambda d: d["detections"].insert(1, copy.deepcopy(d["detections"][0])),
        "duplicate_observation",
        "detections[1]",
    ),
    ("unknown field", set_at(["cameras", 0, "fov"], 1.0), "unknown_field", "cameras[0].fov"),
    ("too few", lambda d: d.__setitem__("detections", d["detections"][:2]), "too_few_frames", "detections"),
    ("frame past 2^53", set_at(["detections", 3, "frame"], 2**63), "malformed_input", "detections[3].frame"),
]


@pytest.mark.parametrize(("name", "change", "code", "field"), CASES, ids=[c[0] for c in CASES])
def test_tag_refusal_names_the_field(
    name: str, change: Callable[[dict[str, Any]], None], code: str, field: str
) -> None:
    doc = copy.deepcopy(BASE)
    change(doc)
    with pytest.raises(InputError) as err:
        tags_from_json(doc)
    assert (err.value.code, err.value.field) == (code, field)


def test_unknown_tag_id_is_a_warning() -> None:
    doc = copy.deepcopy(BASE)
    doc["detections"][0]["id"] = 586
    data = tags_from_json(doc)
    assert any("586" in w for w in data.warnings)
    assert len(data.det_frame) == len(BASE["detections"]) - 1


def test_cli_level_b_round_trip_and_refusal(tmp_path: Path) -> None:
    runner = CliRunner()
    r = runner.invoke(app, ["simulate", "--level", "B", "--out", str(tmp_path), "--seed", "4", "--frames", "40"])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["estimate", str(tmp_path / "tags.json"), "--json"])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["level"] == "B" and doc["coverage"] >= 0.98
    truth = json.loads((tmp_path / "truth.json").read_text())
    err = [
        np.linalg.norm(np.array(p["T_world_body"]["t_m"]) - np.array(truth["frames"][p["frame"]]["t_m"]))
        for p in doc["poses"]
        if p["status"] == "measured"
    ]
    assert np.median(err) < 0.001
    bad = json.loads((tmp_path / "tags.json").read_text())
    bad["cameras"][0]["K"][2][0] = 1.0
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    r = runner.invoke(app, ["estimate", str(tmp_path / "bad.json"), "--json"])
    assert r.exit_code == 2 and "cameras[0].K" in r.output and len(r.output.strip().splitlines()) == 1


def test_mangled_documents_are_refused_never_crash() -> None:
    """Every leaf of a small document replaced by values of the wrong kind: an InputError, or an
    input that is estimated."""
    doc = copy.deepcopy(BASE)
    doc["detections"] = doc["detections"][:12]

    def leaves(node: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
        if isinstance(node, dict):
            return [p for k, v in node.items() for p in leaves(v, (*path, k))]
        if isinstance(node, list):
            return [p for i, v in enumerate(node[:3]) for p in leaves(v, (*path, i))]
        return [path]

    wrong: list[Any] = ["x", None, True, -1, 1e300, [], {}]
    for path in leaves(doc):
        for value in wrong:
            bad = copy.deepcopy(doc)
            target = bad
            for p in path[:-1]:
                target = target[p]
            target[path[-1]] = value
            try:
                data = tags_from_json(bad)
            except InputError:
                continue
            estimate_tag_poses(data)  # a valid (if odd) input is estimated without an error


def test_client_model_reads_the_tag_result() -> None:
    from tumblescan_client.results import result_model

    sim = simulate_tags(TagSimConfig(frames=30), 6)
    result = estimate_tag_poses(tags_from_json(sim.document()), TagPoseOptions(motion_prior="constant_velocity"))
    typed = result_model("marker-pose-graph").model_validate_json(result.model_dump_json())
    assert typed.model_dump(mode="json") == result.model_dump(mode="json")
    assert typed.level == "B" and typed.residuals.rms_px is not None  # type: ignore[attr-defined]


def test_one_small_tag_a_frame_does_not_flip() -> None:
    """One detection a frame (a random camera's random tag): IPPE's two poses fit one small tag
    about equally; continuity with the previous frame picks the right one."""
    sim = simulate_tags(TagSimConfig(frames=150, outlier_fraction=0.0, miss_fraction=0.0, gaps=0), 0)
    rng = np.random.default_rng(0)
    by_frame: dict[int, list[int]] = {}
    for i, f in enumerate(sim.det_frame):
        by_frame.setdefault(f, []).append(i)
    keep = sorted(int(rng.choice(v)) for v in by_frame.values())
    for name in ("det_frame", "det_cam", "det_tag", "corners_px", "outlier"):
        setattr(sim, name, [getattr(sim, name)[i] for i in keep])
    result = estimate_tag_poses(tags_from_json(sim.document()))
    ev = evaluate(result, sim.truth())
    assert ev["max_rot_deg"] < 10  # no flipped frame
    assert ev["ratio"] <= 1.3 and ev["coverage"] >= 0.98
    assert any("nearest the previous frame" in w for w in result.warnings)
