"""Estimate every target's position, frame by frame, from two stations' bearings.

The recipe (``method="ml"``): per frame, candidate pairs by the epipolar angle, the χ² gate,
ML triangulation and a one-to-one assignment that may leave detections unassociated; ambiguous
frames re-assigned with the pairs other frames support (station angle tracks); then the fixes
are linked into tracks and each track's motion is fitted. ``method="paper"`` runs the paper's
Δh matching and Mean Shift correction instead, on the same input and into the same document.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from .._typing import IntArray, Progress, no_progress
from .associate import FrameFixes, assign_frame, gated_candidates, observations
from .epipolar import baseline_basis
from .geometry import take_rows, triangulate
from .inputs import BearingsInput
from .multiframe import associate_frames
from .options import EstimateOptions
from .paper import common_frame, paper_correct, paper_match
from .result import RESULT_SCHEMA
from .smooth import fit_tracks
from .tracks import link_tracks


def estimate(
    inp: BearingsInput, options: EstimateOptions | None = None, progress: Progress = no_progress
) -> dict[str, Any]:
    """The ``tumblescan.bearings.result/1`` document (status ``succeeded``) for a validated input."""
    options = options or EstimateOptions()
    _load_libraries(inp.frame)
    start = time.perf_counter()
    warnings: list[str] = []
    # 1. Associate and triangulate each frame.
    fixes = _frames_ml(inp, options, progress) if options.method == "ml" else _frames_paper(inp, options, progress)
    # Only finite fixes are reported (a degenerate pair's detections stay unassociated).
    fixes = [_finite(fx) for fx in fixes]
    t_assoc = time.perf_counter()
    # 2. Link the fixes into tracks (the paper's method then corrects points along its tracks).
    track_ids: list[IntArray] | None = None
    if options.link_tracks or options.method == "paper":
        progress("linking tracks", 0.8)
        track_ids = link_tracks(
            [f.t_s for f in inp.frames],
            [fx.p_job_m for fx in fixes],
            [fx.cov_m2 for fx in fixes],
            max_speed_m_s=options.max_speed_m_s,
            max_gap_frames=options.max_gap_frames,
        )
    if options.method == "paper":
        assert track_ids is not None
        fixes = _paper_tracks(inp, options, fixes, track_ids)
        keep = [_finite_rows(fx) for fx in fixes]
        fixes = [_finite(fx) for fx in fixes]
        track_ids = [ids[k] for ids, k in zip(track_ids, keep, strict=True)]
        shared = sum(len(fx) - np.unique(fx.i2).size for fx in fixes)
        if shared:
            warnings.append(f"paper method: {shared} station-2 detections were used by more than one target")
    tracks: list[dict[str, Any]] = []
    if track_ids is not None and options.link_tracks:
        tracks = fit_tracks(
            [f.t_s for f in inp.frames],
            [f.index for f in inp.frames],
            [fx.p_job_m for fx in fixes],
            [fx.cov_m2 for fx in fixes],
            track_ids,
            orbital=inp.frame == "ecef",
        )
    t_link = time.perf_counter()
    # 3. The result document.
    progress("writing the result", 0.95)
    doc = _document(inp, fixes, track_ids if options.link_tracks else None, options, warnings)
    doc["tracks"] = tracks
    # The summary counts what ``tracks[]`` lists (the fitted tracks); the track ids too short to
    # fit (fewer than MIN_FIXES fixes), which targets still carry, are counted apart.
    linked = len(np.unique(np.concatenate(track_ids))) if options.link_tracks and track_ids else 0
    doc["summary"]["tracks"] = len(tracks)
    doc["summary"]["short_tracks"] = linked - len(tracks)
    doc["timings_ms"] = {
        "associate": 1e3 * (t_assoc - start),
        "tracks": 1e3 * (t_link - t_assoc),
        "total": 1e3 * (time.perf_counter() - start),
    }
    return doc


def _load_libraries(frame: str) -> None:
    """Import the libraries the steps use lazily, so ``timings_ms`` measures the work alone."""
    import importlib

    for name in ("scipy.optimize", "scipy.sparse.csgraph", "scipy.spatial", "pymap3d" if frame == "ecef" else ""):
        if name:
            importlib.import_module(name)


def _frames_ml(inp: BearingsInput, options: EstimateOptions, progress: Progress) -> list[FrameFixes]:
    basis = baseline_basis(inp.stations)
    cands = []
    for n, fr in enumerate(inp.frames):
        progress("associating", 0.7 * n / len(inp.frames))
        cands.append(gated_candidates(inp.stations, basis, fr.detections, options.gate_chi2))
    if options.multi_frame and len(inp.frames) > 1:
        progress("associating across frames", 0.7)
        return associate_frames(
            inp.frames,
            inp.stations,
            cands,
            gate=options.gate_chi2,
            ambiguity_margin=options.ambiguity_margin_chi2,
            max_rate_rad_s=np.radians(options.max_angular_rate_deg_s),
        )
    return [
        assign_frame(
            c,
            len(fr.detections[0]),
            len(fr.detections[1]),
            gate=options.gate_chi2,
            ambiguity_margin=options.ambiguity_margin_chi2,
        )
        for fr, c in zip(inp.frames, cands, strict=True)
    ]


def _finite_rows(fx: FrameFixes) -> np.ndarray:
    return (
        np.all(np.isfinite(fx.p_job_m), axis=1)
        & np.all(np.isfinite(fx.cov_m2), axis=(1, 2))
        & np.isfinite(fx.chi2)
        & np.all(np.isfinite(fx.range_m), axis=1)
        & np.isfinite(fx.parallax_rad)
    )


def _finite(fx: FrameFixes) -> FrameFixes:
    keep = _finite_rows(fx)
    if keep.all():
        return fx
    return take_rows(fx, keep)


def _describe(
    inp: BearingsInput, f: int, i1: IntArray, i2: IntArray, p_job_m: np.ndarray, corrected: np.ndarray
) -> FrameFixes:
    """A frame's fixes at given positions: covariance (the bound there), χ², ranges, parallax."""
    dets = inp.frames[f].detections
    fix = triangulate(inp.stations, observations(dets, i1, i2), p0_job_m=p_job_m, iterations=0)
    return FrameFixes(
        i1=i1,
        i2=i2,
        p_job_m=fix.p_job_m,
        cov_m2=fix.cov_m2,
        chi2=fix.chi2,
        range_m=fix.range_m,
        parallax_rad=fix.parallax_rad,
        ambiguous=np.zeros(i1.size, dtype=bool),
        corrected=corrected,
        n1=len(dets[0]),
        n2=len(dets[1]),
    )


def _frames_paper(inp: BearingsInput, options: EstimateOptions, progress: Progress) -> list[FrameFixes]:
    cf = common_frame(inp.stations, inp.frame)
    out = []
    for n, fr in enumerate(inp.frames):
        progress("matching (paper)", 0.8 * n / len(inp.frames))
        m = paper_match(inp.stations, cf, fr.detections, gate_sigma=options.paper_gate_sigma)
        p_job = cf.origin_job_m + m.p_enu_m @ cf.R_job_from_enu.T
        out.append(_describe(inp, n, m.i1, m.i2, p_job, np.zeros(m.i1.size, dtype=bool)))
    return out


def _paper_tracks(
    inp: BearingsInput, options: EstimateOptions, fixes: list[FrameFixes], track_ids: list[IntArray]
) -> list[FrameFixes]:
    """The paper's direction histogram + Mean Shift + line fit, track by track."""
    cf = common_frame(inp.stations, inp.frame)
    frame_of = np.concatenate([np.full(len(fx), f) for f, fx in enumerate(fixes)]).astype(np.int64)
    row_of = np.concatenate([np.arange(len(fx)) for fx in fixes]).astype(np.int64)
    tid = np.concatenate(track_ids) if track_ids else np.zeros(0, dtype=np.int64)
    p_enu = np.concatenate([(fx.p_job_m - cf.origin_job_m) @ cf.R_job_from_enu for fx in fixes])
    t = np.array([inp.frames[f].t_s for f in frame_of])
    replaced = np.zeros(tid.size, dtype=bool)
    order = np.argsort(tid, kind="stable")
    for members in np.split(order, np.flatnonzero(np.diff(tid[order])) + 1):
        if members.size >= 3:
            p_new, bad = paper_correct(t[members], p_enu[members], radius_deg=options.paper_radius_deg)
            p_enu[members] = p_new
            replaced[members] = bad
    out = []
    for f, fx in enumerate(fixes):
        sel = frame_of == f
        rows = row_of[sel]
        p_job = np.empty_like(fx.p_job_m)
        p_job[rows] = cf.origin_job_m + p_enu[sel] @ cf.R_job_from_enu.T
        corr = np.zeros(len(fx), dtype=bool)
        corr[rows] = replaced[sel]
        out.append(_describe(inp, f, fx.i1, fx.i2, p_job, corr) if corr.any() else fx)
    return out


def _document(
    inp: BearingsInput,
    fixes: list[FrameFixes],
    track_ids: list[IntArray] | None,
    options: EstimateOptions,
    warnings: list[str],
) -> dict[str, Any]:
    s1, s2 = inp.stations[0].id, inp.stations[1].id
    geodetic = _geodetic([fx.p_job_m for fx in fixes]) if inp.frame == "ecef" else None
    frames = []
    n_amb = 0
    unassoc_total = {s1: 0, s2: 0}
    for f, (fr, fx) in enumerate(zip(inp.frames, fixes, strict=True)):
        d1, d2 = fr.detections
        sigma = np.sqrt(np.abs(np.diagonal(fx.cov_m2, axis1=1, axis2=2)))
        low = np.degrees(fx.parallax_rad) < options.low_parallax_deg
        n_amb += int(fx.ambiguous.sum())
        targets = []
        cols = zip(
            fx.i1.tolist(),
            fx.i2.tolist(),
            fx.p_job_m.tolist(),
            fx.cov_m2.tolist(),
            sigma.tolist(),
            fx.chi2.tolist(),
            fx.range_m.tolist(),
            np.degrees(fx.parallax_rad).tolist(),
            strict=True,
        )
        for k, (a, b, p, c, s, chi2, r, par) in enumerate(cols):
            flags = [
                name
                for name, on in (
                    ("ambiguous", fx.ambiguous[k]),
                    ("low_parallax", low[k]),
                    ("corrected_by_track", fx.corrected[k]),
                )
                if on
            ]
            target: dict[str, Any] = {
                "id": f"F{fr.index}T{k}",
                "position_m": p,
                "cov_m2": c,
                "sigma_m": s,
                "detections": {s1: d1.ids[a], s2: d2.ids[b]},
                "chi2": chi2,
                "range_m": r,
                "parallax_deg": par,
                "flags": flags,
            }
            if track_ids is not None:
                target["track"] = f"K{int(track_ids[f][k])}"
            if geodetic is not None:
                target["geodetic"] = geodetic[f][k]
            targets.append(target)
        used1 = np.zeros(len(d1), dtype=bool)
        used2 = np.zeros(len(d2), dtype=bool)
        used1[fx.i1] = True
        used2[fx.i2] = True
        unassoc = {s1: [d1.ids[i] for i in np.flatnonzero(~used1)], s2: [d2.ids[i] for i in np.flatnonzero(~used2)]}
        unassoc_total[s1] += len(unassoc[s1])
        unassoc_total[s2] += len(unassoc[s2])
        frames.append({"index": fr.index, "t": fr.t_s, "targets": targets, "unassociated": unassoc})
    return {
        "schema": RESULT_SCHEMA,
        "status": "succeeded",
        "kind": "bearings",
        "frame": inp.frame,
        "frames": frames,
        "summary": {
            "targets": sum(len(fx) for fx in fixes),
            "ambiguous": n_amb,
            "unassociated": unassoc_total,
            "tracks": 0,
            "short_tracks": 0,
            "method": options.method,
        },
        "warnings": warnings,
    }


def _geodetic(p_job_m: list[np.ndarray]) -> list[list[dict[str, float]]]:
    import pymap3d

    allp = np.concatenate(p_job_m) if p_job_m else np.zeros((0, 3))
    if allp.shape[0] == 0:
        return [[] for _ in p_job_m]
    lat, lon, h = pymap3d.ecef2geodetic(allp[:, 0], allp[:, 1], allp[:, 2])
    lat, lon, h = (np.nan_to_num(np.atleast_1d(x), nan=0.0, posinf=0.0, neginf=0.0) for x in (lat, lon, h))
    rows = [
        {"lat_deg": a, "lon_deg": b, "height_m": c}
        for a, b, c in zip(
            np.atleast_1d(lat).tolist(), np.atleast_1d(lon).tolist(), np.atleast_1d(h).tolist(), strict=True
        )
    ]
    out, n = [], 0
    for p in p_job_m:
        out.append(rows[n : n + p.shape[0]])
        n += p.shape[0]
    return out
