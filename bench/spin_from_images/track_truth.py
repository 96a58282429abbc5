"""Line tracks scored against the simulator's truth: which body edge each tracked segment lies on.

The simulator (``spin_rate.simulate``) knows the target's boxes and the motion; every box edge is a
3D line, projected into each frame it gives the true image line. Each observed segment is labelled
with the body line (edges on one 3D line, e.g. the long edges of adjacent wing sub-panels, are one
line) whose projection is nearest to both its ends; a track whose segments carry more than one
label, or lie far from every true line, mixes edges.

    PYTHONPATH=service:client python -m bench.spin_from_images.track_truth bench/out/spin_cache_512/oblique_110_noisy
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tumblescan._typing import FloatArray
from tumblescan.spin_rate import simulate
from tumblescan.spin_rate.rotation import rot


@dataclass(frozen=True)
class TrueMotion:
    """The simulated motion and the body's 3D lines: points ``p`` and unit directions ``d`` (L, 3,
    body frame, m), ``X_cam(t) = c_m + v t + Rot(a, ω t) R_ref X_body``; K (3, 3)."""

    K: FloatArray
    R_ref: FloatArray
    axis: FloatArray
    omega_rad_s: float
    c_m: FloatArray
    v_m_s: FloatArray
    lines_p: FloatArray
    lines_d: FloatArray
    segments_body: FloatArray  # (E, 2, 3) every box edge
    line_of_edge: np.ndarray  # (E,) index into lines_p

    def image_lines(self, t_s: float) -> FloatArray:
        """The body lines' homogeneous image lines (L, 3) at time ``t_s``, normalised so that
        ``l · (u, v, 1)`` is a distance in px."""
        R = rot(self.axis, self.omega_rad_s * t_s)[0] @ self.R_ref
        c = self.c_m + self.v_m_s * t_s
        X = self.lines_p @ R.T + c
        D = self.lines_d @ R.T
        lines = np.cross(X @ self.K.T, D @ self.K.T)
        return np.asarray(lines / np.linalg.norm(lines[:, :2], axis=1, keepdims=True), dtype=float)

    def image_edges(self, t_s: float) -> FloatArray:
        """Every box edge's projected end points (E, 2, 2) px at ``t_s``."""
        R = rot(self.axis, self.omega_rad_s * t_s)[0] @ self.R_ref
        c = self.c_m + self.v_m_s * t_s
        X = self.segments_body @ R.T + c
        x = X @ self.K.T
        return np.asarray(x[..., :2] / x[..., 2:], dtype=float)


def true_motion(seed: int, kind: str) -> TrueMotion:
    """The geometry of ``simulate_sequence(seed, kind)`` without rendering (the renderer and the
    sensor replaced by zeros; neither draws from the geometry's random stream)."""
    captured: dict[str, Any] = {}
    real_truth, real_render, real_expose = simulate._truth, simulate.render_exposure, simulate.expose

    def grab(*args: Any) -> dict[str, Any]:
        names = ["kind", "target", "camera", "R_ref", "a", "omega", "c_m", "v_m_s", "t_s", "dt", "exposure_s", "n_blur"]
        captured.update(zip(names, args, strict=True))
        return {}

    class _Blank:
        def __init__(self, h: int, w: int) -> None:
            self.radiance = np.zeros((h, w))

    def blank(mesh: Any, cam: Any, poses: Any, sun: Any) -> _Blank:
        return _Blank(cam.height_px, cam.width_px)

    def dark(radiance: Any, sensor: Any, rng: Any) -> np.ndarray:
        return np.zeros(radiance.shape, np.uint8)

    try:
        simulate._truth = grab  # type: ignore[assignment]
        simulate.render_exposure = blank  # type: ignore[assignment]
        simulate.expose = dark
        simulate.simulate_sequence(seed, kind)  # type: ignore[arg-type]
    finally:
        simulate._truth, simulate.render_exposure, simulate.expose = real_truth, real_render, real_expose
    cam = captured["camera"]
    K = np.array([[cam.fx_px, cam.skew, cam.cx_px], [0.0, cam.fy_px, cam.cy_px], [0.0, 0.0, 1.0]])
    V = captured["target"].mesh.vertices_m.reshape(-1, 8, 3)  # one box per 8 vertices
    pairs = [(i, j) for i in range(8) for j in range(i + 1, 8) if bin(i ^ j).count("1") == 1]
    segs = np.array([[box[i], box[j]] for box in V for i, j in pairs])
    # Group edges on one 3D line (1 mm, 0.1°).
    lines_p: list[FloatArray] = []
    lines_d: list[FloatArray] = []
    label = np.zeros(len(segs), dtype=int)
    for k, (p, q) in enumerate(segs):
        d = (q - p) / np.linalg.norm(q - p)
        for m, (lp, ld) in enumerate(zip(lines_p, lines_d, strict=True)):
            if abs(float(d @ ld)) > np.cos(np.radians(0.1)) and np.linalg.norm(np.cross(p - lp, ld)) < 1e-3:
                label[k] = m
                break
        else:
            label[k] = len(lines_p)
            lines_p.append(p)
            lines_d.append(d)
    return TrueMotion(
        K, captured["R_ref"], captured["a"], float(captured["omega"]), captured["c_m"], captured["v_m_s"],
        np.array(lines_p), np.array(lines_d), segs, label,
    )  # fmt: skip


def label_segments(motion: TrueMotion, t_s: float, ends_px: FloatArray) -> tuple[np.ndarray, FloatArray]:
    """For segments ``ends_px`` (S, 2, 2) seen at ``t_s``: the body line (S,) whose image passes
    nearest to both ends among the lines with an edge overlapping the segment (-1 when none), and
    that larger end distance (S,) px."""
    lines = motion.image_lines(t_s)
    edges = motion.image_edges(t_s)
    eh = np.concatenate([ends_px, np.ones((*ends_px.shape[:2], 1))], axis=2)
    dist = np.abs(np.einsum("ski,li->slk", eh, lines)).max(axis=2)  # (S, L)
    # Only lines with an edge that overlaps the segment along its direction (2 px slack).
    near = np.full(dist.shape, False)
    for e, m in zip(edges, motion.line_of_edge, strict=True):
        t = e[1] - e[0]
        L = float(np.linalg.norm(t))
        if L < 1e-6:
            continue
        t = t / L
        s = (ends_px - e[0]) @ t  # (S, 2)
        lo, hi = s.min(axis=1), s.max(axis=1)
        near[:, m] |= (hi > -2.0) & (lo < L + 2.0)
    dist = np.where(near, dist, np.inf)
    best = np.argmin(dist, axis=1)
    d = dist[np.arange(len(best)), best]
    return np.where(np.isfinite(d), best, -1), np.asarray(d, dtype=float)


def score_tracks(
    motion: TrueMotion, t_s: FloatArray, tracks: list[dict[int, int]], segments: list[FloatArray], gate_px: float = 1.5
) -> list[dict[str, Any]]:
    """Each track (frame -> segment index): its segments' true lines and distances, and whether
    it is clean (one line, every segment within ``gate_px``)."""
    labelled = [
        label_segments(motion, float(t_s[f]), segments[f]) if len(segments[f]) else None for f in range(len(t_s))
    ]
    out = []
    for j, tr in enumerate(tracks):
        frames = sorted(tr)
        lab = [int(labelled[f][0][tr[f]]) for f in frames]  # type: ignore[index]
        dist = [float(labelled[f][1][tr[f]]) for f in frames]  # type: ignore[index]
        main = max(set(lab), key=lab.count)
        # Distance to the track's main line: a switch to a line less than a pixel away (the two
        # edges of a 3 cm panel side) is no error; a switch to another edge is.
        to_main = [float(np.abs(main_line_dist(motion, float(t_s[f]), segments[f][tr[f]], main))) for f in frames]
        out.append({
            "track": j, "frames": frames, "lines": lab, "dist_px": [round(x, 2) for x in dist],
            "to_main_px": [round(x, 1) for x in to_main],
            "main_line": main, "n_lines": len(set(lab)), "max_dist_px": max(dist),
            "clean": max(to_main) <= gate_px,
        })  # fmt: skip
    return out


def main_line_dist(motion: TrueMotion, t_s: float, ends_px: FloatArray, line: int) -> float:
    """The larger distance (px) of the segment's ends (2, 2) to body line ``line``'s image at ``t_s``."""
    lv = motion.image_lines(t_s)[line]
    return float(np.max(np.abs(ends_px @ lv[:2] + lv[2])))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("sequence", type=Path)
    ap.add_argument("--min-frames", type=int, default=3)
    ap.add_argument("--final", action="store_true", help="score the estimate's final tracks, and fit from the truth")
    args = ap.parse_args()
    from tumblescan.spin_rate.features import extract
    from tumblescan.spin_rate.pipeline import load_input

    seq = load_input(args.sequence / "meta.json")
    kind, seed = args.sequence.name.split("_")[:2]
    motion = true_motion(int(seed), kind)
    truth = json.loads((args.sequence / "truth.json").read_text())
    assert abs(np.degrees(motion.omega_rad_s) - truth["rate_deg_s"]) < 1e-9
    if args.final:
        final(seq, motion)
        return
    feats = extract(seq.grays, seq.full_scale, seq.meta.prior.target_polarity, lambda *a: None)
    ideal = [np.array([seq.meta.pinhole.undistort(e) for e in s.ends_px]).reshape(-1, 2, 2) for s in feats.segments]
    tracks = [tr.members for tr in feats.tracks if len(tr) >= args.min_frames]
    rows = score_tracks(motion, seq.t_s, tracks, ideal)
    for r in rows:
        flag = "ok " if r["clean"] else "BAD"
        print(f"{flag} track {r['track']:2d} frames {r['frames'][0]:2d}-{r['frames'][-1]:2d} n={len(r['frames']):2d} "
              f"lines {r['lines']} dist {r['dist_px']} to main {r['to_main_px']}")  # fmt: skip
    bad = sum(not r["clean"] for r in rows)
    print(f"{len(rows)} tracks of {args.min_frames}+ frames, {bad} not clean")


def final(seq: Any, motion: TrueMotion) -> None:
    """The estimate's final tracks scored against the truth, and the rigid fit on them started
    from the truth beside the estimate's winner."""
    from tumblescan.spin_rate.options import EstimateOptions
    from tumblescan.spin_rate.pipeline import run
    from tumblescan.spin_rate.rigid import Observations, fit_rigid

    seq.meta.options.return_tracks = True
    res = run(seq, EstimateOptions())
    tr = res.tracks
    assert tr is not None
    frames = np.array([o.frame for o in tr])
    track = np.array([o.track for o in tr])
    ends = np.array([o.ends_px for o in tr], dtype=float)
    segments = [ends[frames == f] for f in range(len(seq.t_s))]
    index = np.zeros(len(tr), dtype=int)
    for f in range(len(seq.t_s)):
        index[frames == f] = np.arange(int((frames == f).sum()))
    tracks = [{int(f): int(i) for f, i in zip(frames[track == j], index[track == j], strict=True)}
              for j in range(int(track.max()) + 1)]  # fmt: skip
    for r in score_tracks(motion, seq.t_s, tracks, segments):
        flag = "ok " if r["clean"] else "BAD"
        print(f"{flag} track {r['track']:2d} n={len(r['frames']):2d} frames {r['frames']} lines {r['lines']} "
              f"to main {r['to_main_px']}")  # fmt: skip
    K = seq.meta.pinhole.K
    obs = Observations.build(track, seq.t_s[frames], ends, K)
    c0 = motion.c_m / motion.c_m[2]
    truth_fit = fit_rigid(obs, motion.omega_rad_s, motion.axis, c0, float(seq.t_s[0]))
    win = fit_rigid(obs, np.radians(res.spin.rate_deg_s), np.array(res.spin.axis_camera), c0, float(seq.t_s[0]))
    print(
        f"estimate {res.spin.rate_deg_s:.4f} deg/s (truth {np.degrees(motion.omega_rad_s):.4f}), "
        f"rms {res.quality.fit_rms_px}"
    )
    for name, fit in (("from truth", truth_fit), ("from winner", win)):
        print(f"{name}: {np.degrees(fit.omega_rad_s):.4f} deg/s, cost {fit.cost:.4g}, rms {fit.rms_px:.3f} px")


if __name__ == "__main__":
    main()
