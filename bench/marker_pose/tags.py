"""marker-pose-graph benchmark, levels B (tag corners) and C (images): tag pose error against the
per-frame tag bound (Fisher information of the corner projections), coverage, NEES and time.

Level B: the simulator's detections (0.25 px, misses, 0.3 % gross errors, gaps), 500 frames.
Level C: rendered 1024 x 1024 images, detected with pupil-apriltags (ours) or OpenCV's ArUco
detector, the corner sigma estimated from the residuals (the default with images). The bound is
the one given the detector's corners: over the tags it found, at its RMS corner error against the
exact projections (printed beside it, with the share of the tags facing a camera within 70 deg
that it found). Image corner errors are not independent (mostly radial: a tag looks slightly too
large or small), so the bound is a reference, not a floor.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from tumblescan.marker_pose.evaluate import evaluate
from tumblescan.marker_pose.images_io import detect_tags, read_image_set
from tumblescan.marker_pose.options import ImagePoseOptions, TagPoseOptions
from tumblescan.marker_pose.tag_camera import RigArrays, project, tag_corners_body, to_camera
from tumblescan.marker_pose.tag_estimate import estimate_tag_poses
from tumblescan.marker_pose.tag_render import detectable, image_config, write_image_simulation
from tumblescan.marker_pose.tag_simulate import TagSimConfig, TagSimulation, simulate_tags
from tumblescan.marker_pose.tags_io import TagInput, tags_from_json

MOTIONS = ("paper", "tumble")
TAG_GOAL = 1.3

HEADER = [
    "level",
    "method",
    "motion",
    "n",
    "ratio med/max",
    "cov min",
    "worst",
    "NEES/6 med",
    "3sig deg/mm med",
    "corner rms px",
    "found",
    "time s med",
    "pass",
]


def level_b(seeds: int, frames: int = 500) -> list[dict[str, Any]]:
    runs = []
    for motion in MOTIONS:
        for seed in range(seeds):
            sim = simulate_tags(TagSimConfig(motion=motion, frames=frames), seed)
            data = tags_from_json(sim.document())
            truth = sim.truth()
            for name, opts in (("ours", {}), ("ours+cv", {"motion_prior": "constant_velocity"})):
                started = time.perf_counter()
                result = estimate_tag_poses(data, TagPoseOptions.model_validate(opts))
                runs.append(
                    {
                        "level": "B",
                        "method": name,
                        "motion": motion,
                        "time_s": time.perf_counter() - started,
                        "corner_rms_px": sim.config.pixel_sigma_px,
                        **evaluate(result, truth),
                    }
                )
    return runs


def level_c(seeds: int, frames: int = 30) -> list[dict[str, Any]]:
    runs = []
    for motion in MOTIONS:
        for seed in range(seeds):
            config = image_config(motion=motion, frames=frames)
            with tempfile.TemporaryDirectory() as tmp:
                archive, _ = write_image_simulation(Path(tmp), config, seed)
                images = read_image_set(archive)
                sim = simulate_tags(config, seed)
                expected = len(detectable(sim))
                for name, detector in (("apriltag", "apriltag"), ("aruco", "aruco")):
                    opts = ImagePoseOptions(detector=detector)
                    started = time.perf_counter()
                    data, info = detect_tags(images, opts)
                    result = estimate_tag_poses(data, opts, level="C", detection=info)
                    elapsed = time.perf_counter() - started
                    # The bound given the detector's corners: over the tags it found, at its own
                    # corner error against the exact projections.
                    rms = corner_rms(sim, data)
                    cams = [replace(c, pixel_sigma_px=rms) for c in sim.cameras]
                    found = list(
                        zip(data.det_frame.tolist(), data.det_cam.tolist(), data.det_tag.tolist(), strict=True)
                    )
                    truth = replace(sim, cameras=cams).truth(found)
                    runs.append(
                        {
                            "level": "C",
                            "method": name,
                            "motion": motion,
                            "time_s": elapsed,
                            "corner_rms_px": rms,
                            "found": len(found) / max(expected, 1),
                            **evaluate(result, truth),
                        }
                    )
    return runs


def corner_rms(sim: TagSimulation, data: TagInput) -> float:
    """The detector's RMS corner error per image axis [px] against the exact projections."""
    if not len(data.det_frame):
        return float("nan")
    rig = RigArrays.of(sim.cameras)
    corners = tag_corners_body(sim.T_body_tag, sim.config.tag_size_m)[data.det_tag]
    k = data.det_frame
    pw = np.einsum("nij,npj->npi", sim.R_world_body[k], corners) + sim.t_world_m[k][:, None]
    uv = project(to_camera(pw, data.det_cam, rig), data.det_cam, rig)
    return float(np.sqrt(np.mean((data.corners_px - uv) ** 2)))


def _median(runs: list[dict[str, Any]], key: str) -> float:
    return float(np.median([r[key] for r in runs]))


def summary(runs: list[dict[str, Any]]) -> list[list[object]]:
    rows: list[list[object]] = []
    keys = sorted({(r["level"], r["method"], r["motion"]) for r in runs})
    for level, method, motion in keys:
        sel = [r for r in runs if (r["level"], r["method"], r["motion"]) == (level, method, motion)]
        ok = sum(
            r["ratio"] <= TAG_GOAL
            and r["coverage"] >= 0.98
            and r["worst_mahalanobis"] <= 8
            and 0.25 <= r["nees_over_6"] <= 4
            for r in sel
        )
        rows.append(
            [
                level,
                method,
                motion,
                len(sel),
                f"{np.median([r['ratio'] for r in sel]):.2f} / {max(r['ratio'] for r in sel):.2f}",
                f"{min(r['coverage'] for r in sel):.3f}",
                f"{max(r['worst_mahalanobis'] for r in sel):.1f}",
                f"{np.median([r['nees_over_6'] for r in sel]):.2f}",
                f"{_median(sel, 'rot_3sigma_deg'):.3f} / {_median(sel, 'pos_3sigma_mm'):.2f}",
                f"{_median(sel, 'corner_rms_px'):.3f}",
                f"{_median(sel, 'found'):.2f}" if "found" in sel[0] else "-",
                f"{np.median([r['time_s'] for r in sel]):.2f}",
                f"{ok}/{len(sel)}",
            ]
        )
    return rows


def timings_b() -> list[list[object]]:
    """Level B, 500 and 10,000 frames of the tagged box (about 12 detections a frame): reading and
    checking the document, then the estimate without and with the motion prior (wall / CPU s)."""
    rows: list[list[object]] = []
    for frames in (500, 10_000):
        doc = simulate_tags(TagSimConfig(frames=frames), 11).document()
        wall, cpu = time.perf_counter(), time.process_time()
        data = tags_from_json(doc)
        read = f"{time.perf_counter() - wall:.2f} / {time.process_time() - cpu:.2f}"
        for name, opts in (("ours", {}), ("ours+cv", {"motion_prior": "constant_velocity"})):
            wall, cpu = time.perf_counter(), time.process_time()
            estimate_tag_poses(data, TagPoseOptions.model_validate(opts))
            rows.append(
                [
                    frames,
                    len(data.det_frame),
                    name,
                    read,
                    f"{time.perf_counter() - wall:.2f} / {time.process_time() - cpu:.2f}",
                ]
            )
    return rows
