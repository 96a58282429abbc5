"""Simulated motion capture of a target carrying markers (level A: 3D marker coordinates).

The rig: four cameras at the top corners of a 6 x 6 x 3 m volume (world frame: floor centre,
z up), looking at its centre. A marker (a retro-reflective sphere on the body, with an outward
normal) is triangulated when its normal is within 80 deg of the direction to at least two
cameras. The tracker is imperfect in the ways the paper and the digest describe: random
dropouts (a reappearing marker gets a new track id), resets that empty a few frames and restart
every track (the paper's segments), gross outliers, swapped identities, static reflections and
glints sliding on the body. The truth holds every pose and the per-frame Cramer-Rao bound over
the inlier markers.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from .._typing import FloatArray
from .geometry import exp_so3, pose_information, quat_wxyz

CAMERAS_M = np.array([[3.0, 3.0, 3.0], [-3.0, 3.0, 3.0], [-3.0, -3.0, 3.0], [3.0, -3.0, 3.0]])
CENTRE_M = np.array([0.0, 0.0, 1.2])
COS_VISIBLE = np.cos(np.radians(80.0))
# A glint this close to its sphere (in noise sigmas) claims the sphere too: both are left out of
# the frame by the estimator (its gate is 5 sigma on noisy points), so the bound leaves it out.
GLINT_CLAIM_SIGMA = 8.0


class SimConfig(BaseModel):
    """What to simulate. Defaults are the paper's case: a 400 mm kite, sinusoidal attitude and
    displacement, 50 Hz for 10 s, sigma = 2.9 mm, 3 resets (4 segments)."""

    model_config = ConfigDict(extra="forbid")

    target: Literal["kite", "box"] = "kite"
    motion: Literal["paper", "tumble"] = "paper"
    frames: int = Field(500, ge=10, le=200_000)
    frame_rate_hz: float = Field(50.0, gt=0)
    point_sigma_m: float = Field(0.0029, ge=0)
    dropout_per_frame: float = Field(0.004, ge=0, le=0.2)
    resets: int = Field(3, ge=0)
    outlier_fraction: float = Field(0.005, ge=0, le=0.2)
    swaps: int = Field(2, ge=0)
    reflections: int = Field(2, ge=0)
    glints: int = Field(2, ge=0)
    labels: bool = False
    with_layout: bool = True


@dataclass
class Target:
    ids: list[str]
    p_body_m: FloatArray  # (M, 3)
    n_body: FloatArray  # (M, 3) outward unit normals


@dataclass
class Simulation:
    config: SimConfig
    target: Target
    t_s: FloatArray  # (F,)
    R_world_body: FloatArray  # (F, 3, 3)
    t_world_m: FloatArray  # (F, 3)
    frame: list[int] = field(default_factory=list)  # per observation
    track: list[str] = field(default_factory=list)
    xyz_m: list[list[float]] = field(default_factory=list)
    marker: list[int] = field(default_factory=list)  # true marker index, -1 for a reflection or glint
    label: list[int] = field(default_factory=list)  # the tracker's label (follows the track)
    outlier: list[bool] = field(default_factory=list)
    excluded: set[tuple[int, int]] = field(default_factory=set)  # (frame, marker) claimed by a glint too

    def document(self) -> dict[str, Any]:
        """The input document (``tumblescan.markers.v1``)."""
        obs: list[dict[str, Any]] = []
        for i, f in enumerate(self.frame):
            o: dict[str, Any] = {"frame": f, "t": round(float(self.t_s[f]), 9), "track": self.track[i]}
            o["xyz"] = [round(v, 7) for v in self.xyz_m[i]]
            if self.config.labels and self.label[i] >= 0:
                o["marker"] = self.target.ids[self.label[i]]
            obs.append(o)
        doc: dict[str, Any] = {
            "format": "tumblescan.markers.v1",
            "units": {"length": "m", "time": "s"},
            "frame": "world",
            "frame_rate_hz": self.config.frame_rate_hz,
            "sensor": {"point_sigma_m": self.config.point_sigma_m},
            "observations": obs,
        }
        if self.config.with_layout:
            doc["body"] = {
                "markers": [
                    {"id": m, "xyz": [round(float(v), 9) for v in p]}
                    for m, p in zip(self.target.ids, self.target.p_body_m, strict=True)
                ]
            }
        return doc

    def truth(self) -> dict[str, Any]:
        """Every pose, the inlier markers and the per-frame bound (with the layout, and counting only
        the markers that can be self-calibrated without it)."""
        crlb = self.bounds(self_calibrated=False)
        crlb_self = self.bounds(self_calibrated=True)
        frames = []
        inl = self.inliers()
        for k in range(len(self.t_s)):
            c, cs = crlb[k], crlb_self[k]
            frames.append(
                {
                    "frame": k,
                    "t": float(self.t_s[k]),
                    "q_wxyz": quat_wxyz(self.R_world_body[k]).tolist(),
                    "t_m": self.t_world_m[k].tolist(),
                    "inlier_markers": [self.target.ids[m] for m in sorted(inl[k])],
                    "crlb": None if c is None else c.tolist(),
                    "crlb_self_calibrated": None if cs is None else cs.tolist(),
                }
            )
        tracks = {tr: (self.target.ids[m] if m >= 0 else None) for tr, m in zip(self.track, self.marker, strict=True)}
        return {
            "format": "tumblescan.markers.truth.v1",
            "config": self.config.model_dump(mode="json"),
            "layout": {
                "ids": self.target.ids,
                "xyz": self.target.p_body_m.tolist(),
                "normals": self.target.n_body.tolist(),
            },
            "tracks": tracks,
            "frames": frames,
        }

    def inliers(self) -> list[set[int]]:
        """Per frame, the markers measured without a gross error and not claimed by a glint too."""
        out: list[set[int]] = [set() for _ in self.t_s]
        for f, m, bad in zip(self.frame, self.marker, self.outlier, strict=True):
            if m >= 0 and not bad and (f, m) not in self.excluded:
                out[f].add(m)
        return out

    def bounds(self, *, self_calibrated: bool) -> list[FloatArray | None]:
        """``C_k = sigma^2 (sum J_m^T J_m)^-1`` over the inlier markers (order dtheta_world, dp_world).

        Self-calibrated: a marker counts once it was seen in 10 or more frames together with 3 or
        more already-qualified markers (the first frame with 3 or more seeds them)."""
        sigma = max(self.config.point_sigma_m, 1e-6)
        inl = self.inliers()
        qualified: set[int] = set()
        seen_with: dict[int, int] = {}
        out: list[FloatArray | None] = []
        for k, ms in enumerate(inl):
            use = ms
            if self_calibrated:
                if not qualified and len(ms) >= 3:
                    qualified |= ms
                if len(ms & qualified) >= 3:
                    for m in ms - qualified:
                        seen_with[m] = seen_with.get(m, 0) + 1
                        if seen_with[m] >= 10:
                            qualified.add(m)
                use = ms & qualified
            out.append(
                _bound(self.R_world_body[k], self.target.p_body_m[sorted(use)], sigma) if len(use) >= 3 else None
            )
        return out


def _bound(R: FloatArray, p: FloatArray, sigma: float) -> FloatArray | None:
    info = pose_information(R, p, sigma)
    if np.linalg.cond(info) > 1e12:
        return None
    return np.asarray(np.linalg.inv(info))


def asymmetric_layout(rng: np.random.Generator, target: str) -> Target:
    """A random layout whose pairwise distances are at least 12 mm apart for the 4-marker kite and
    6 mm apart for the 8-marker box (its 28 distances cannot all be 12 mm apart on its faces), so
    markers can be identified by their distance signature; drawn marker by marker."""
    min_gap_m = 0.012 if target == "kite" else 0.006
    slots = _kite_slots() if target == "kite" else _box_slots()
    for _ in range(1000):
        p: list[FloatArray] = []
        n: list[FloatArray] = []
        for draw in slots:
            for _ in range(500):
                q, normal = draw(rng)
                dists = sorted([*_pair_distances(p), *(float(np.linalg.norm(q - x)) for x in p)])
                if len(dists) < 2 or np.min(np.diff(dists)) >= min_gap_m:
                    p.append(q)
                    n.append(normal)
                    break
            else:
                break
        if len(p) == len(slots):
            return Target([f"M{i + 1}" for i in range(len(p))], np.array(p), np.array(n))
    raise RuntimeError("no asymmetric layout found")


def _pair_distances(p: list[FloatArray]) -> list[float]:
    return [float(np.linalg.norm(p[i] - p[j])) for i in range(len(p)) for j in range(i + 1, len(p))]


Slot = Any  # a callable: rng -> (position (3,), normal (3,))


def _kite_slots() -> list[Slot]:
    # Nose, wing tip, tail, wing tip of a 400 mm flat vehicle; markers on top (normals +z).
    base = [
        np.array([0.20, 0.0, 0.0]),
        np.array([0.0, 0.15, 0.0]),
        np.array([-0.18, 0.0, 0.0]),
        np.array([0.0, -0.12, 0.0]),
    ]
    up = np.array([0.0, 0.0, 1.0])
    return [lambda r, b=b: (b + np.array([*r.uniform(-0.03, 0.03, 2), 0.0]), up) for b in base]


def _box_slots() -> list[Slot]:
    # A 440 x 340 x 260 mm box; 8 markers on its faces, with the faces' normals.
    half = np.array([0.22, 0.17, 0.13])

    def on_face(axis: int, sign: float) -> Slot:
        def draw(r: np.random.Generator) -> tuple[FloatArray, FloatArray]:
            q = r.uniform(-0.85, 0.85, 3) * half
            q[axis] = sign * half[axis]
            normal = np.zeros(3)
            normal[axis] = sign
            return q, normal

        return draw

    faces = [(2, 1.0), (2, 1.0), (0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0), (2, -1.0), (1, 1.0)]
    return [on_face(a, s) for a, s in faces]


def motion(rng: np.random.Generator, kind: str, t_s: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(R_world_body (F, 3, 3), t_world_m (F, 3)) of the paper's sinusoids or a tumble."""
    from scipy.spatial.transform import Rotation

    if kind == "paper":
        amp = np.radians(rng.uniform(10.0, 30.0, 3))
        freq = rng.uniform(0.08, 0.2, 3)
        phase = rng.uniform(0, 2 * np.pi, 3)
        ypr = amp * np.sin(2 * np.pi * freq * t_s[:, None] + phase)
        R = np.asarray(Rotation.from_euler("ZYX", ypr).as_matrix())
        damp = rng.uniform(0.1, 0.5, 3) * np.array([1.0, 1.0, 0.4])
        dfreq = rng.uniform(0.05, 0.15, 3)
        dphase = rng.uniform(0, 2 * np.pi, 3)
        t = CENTRE_M + damp * np.sin(2 * np.pi * dfreq * t_s[:, None] + dphase)
        return R, t
    spin = np.radians(rng.uniform(30.0, 90.0)) * rng.choice([-1.0, 1.0])
    prec = np.radians(rng.uniform(5.0, 20.0))
    tilt = exp_so3(np.array([np.radians(rng.uniform(20.0, 60.0)), 0.0, 0.0]))
    R0 = np.asarray(Rotation.random(random_state=int(rng.integers(1 << 31))).as_matrix())
    z = np.array([0.0, 0.0, 1.0])
    R = exp_so3(prec * t_s[:, None] * z) @ tilt @ exp_so3(spin * t_s[:, None] * z) @ R0
    v = rng.uniform(-0.03, 0.03, 3)
    return R, CENTRE_M + v * t_s[:, None]


def visible(R: FloatArray, t: FloatArray, tgt: Target) -> FloatArray:
    """(F, M) bool: a marker is triangulated when its normal faces at least two cameras."""
    p = np.einsum("fij,mj->fmi", R, tgt.p_body_m) + t[:, None]
    n = np.einsum("fij,mj->fmi", R, tgt.n_body)
    d = CAMERAS_M[None, None] - p[:, :, None]
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    cos = np.einsum("fmi,fmci->fmc", n, d)
    return np.asarray((cos > COS_VISIBLE).sum(axis=-1) >= 2)


def simulate(config: SimConfig, seed: int) -> Simulation:
    """Simulate ``config`` with the random generator seeded by ``seed``."""
    rng = np.random.default_rng(seed)
    # 1. Layout and motion.
    tgt = asymmetric_layout(rng, config.target)
    F = config.frames
    t_s = np.arange(F) / config.frame_rate_hz
    R, t = motion(rng, config.motion, t_s)
    sim = Simulation(config, tgt, t_s, R, t)
    seen = visible(R, t, tgt)
    # 2. Tracker resets: a few empty frames, then every track restarts (the paper's segments).
    empty = np.zeros(F, dtype=bool)
    for k in range(config.resets):
        start = int((k + 1) * F / (config.resets + 1) + rng.integers(-F // 20, F // 20 + 1))
        empty[max(start, 1) : max(start, 1) + int(rng.integers(1, 6))] = True
    swap_frames = set(rng.choice(np.arange(F // 10, F), size=min(config.swaps, F // 2), replace=False).tolist())
    M = len(tgt.ids)
    track_of = [-1] * M  # current track number of each marker (-1: none)
    label_of: dict[int, int] = {}
    hidden_until = np.zeros(M, dtype=int)
    next_track = 0
    sigma = config.point_sigma_m
    # 3. Markers, frame by frame.
    for k in range(F):
        if empty[k]:
            track_of = [-1] * M
            continue
        if k in swap_frames:
            live = [m for m in range(M) if track_of[m] >= 0]
            if len(live) >= 2:
                a, b = rng.choice(live, 2, replace=False)
                track_of[a], track_of[b] = track_of[b], track_of[a]
        for m in range(M):
            if not seen[k, m] or k < hidden_until[m]:
                track_of[m] = -1
                continue
            if track_of[m] >= 0 and rng.random() < config.dropout_per_frame:
                track_of[m] = -1
                hidden_until[m] = k + int(rng.integers(1, 4))
                continue
            if track_of[m] < 0:
                track_of[m], next_track = next_track, next_track + 1
                label_of[track_of[m]] = m
            y = R[k] @ tgt.p_body_m[m] + t[k] + rng.normal(0, sigma, 3)
            bad = bool(rng.random() < config.outlier_fraction)
            if bad:
                u = rng.normal(size=3)
                y += u / np.linalg.norm(u) * rng.uniform(0.03, 0.08)
            _add(sim, k, f"T{track_of[m]:05d}", y, m, label_of[track_of[m]], bad)
    # 4. Static reflections and glints sliding on the body, each a track of its own.
    for _ in range(config.reflections):
        k0 = int(rng.integers(0, max(F - 50, 1)))
        p = t[k0] + rng.uniform(-0.3, 0.3, 3)
        name, next_track = f"T{next_track:05d}", next_track + 1
        for k in range(k0, min(k0 + 50, F)):
            if not empty[k]:
                _add(sim, k, name, p + rng.normal(0, sigma, 3), -1, -1, False)
    for _ in range(config.glints):
        k0 = int(rng.integers(0, max(F - 25, 1)))
        m = int(rng.integers(M))
        u = rng.normal(size=3)
        u -= u @ tgt.n_body[m] * tgt.n_body[m]
        v_body = u / np.linalg.norm(u) * rng.uniform(0.05, 0.15)
        start = tgt.p_body_m[m] + v_body / np.linalg.norm(v_body) * rng.uniform(0.002, 0.005)
        name, next_track = f"T{next_track:05d}", next_track + 1
        for k in range(k0, min(k0 + 25, F)):
            if empty[k] or not seen[k, m]:
                continue
            q = start + v_body * (t_s[k] - t_s[k0])
            _add(sim, k, name, R[k] @ q + t[k] + rng.normal(0, sigma, 3), -1, -1, False)
            if np.linalg.norm(q - tgt.p_body_m[m]) < GLINT_CLAIM_SIGMA * max(sigma, 1e-3):
                sim.excluded.add((k, m))
    _sort(sim)
    return sim


def _add(sim: Simulation, k: int, track: str, y: FloatArray, marker: int, label: int, bad: bool) -> None:
    sim.frame.append(k)
    sim.track.append(track)
    sim.xyz_m.append([float(v) for v in y])
    sim.marker.append(marker)
    sim.label.append(label)
    sim.outlier.append(bad)


def _sort(sim: Simulation) -> None:
    order = sorted(range(len(sim.frame)), key=lambda i: (sim.frame[i], sim.track[i]))
    for name in ("frame", "track", "xyz_m", "marker", "label", "outlier"):
        values = getattr(sim, name)
        setattr(sim, name, [values[i] for i in order])
