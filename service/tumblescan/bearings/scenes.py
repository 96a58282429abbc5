"""Simulated scenes (digest §8.1): where the stations are and how the targets move.

Each scene draws two stations and K target trajectories sampled at the frame times, in the
job frame (local ENU metres, or WGS84 ECEF metres for the LEO scene).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from .._typing import FloatArray
from .geometry import (
    MU_EARTH_M3_S2,
    OMEGA_EARTH_RAD_S,
    R_ecef_from_enu,
    Station,
    bearings_of,
    geodetic_to_ecef,
    unit_vectors,
)

SceneName = Literal["paper", "close", "near-collinear", "baseline-plane", "similar-elevation", "swarm", "leo"]
SCENES: tuple[str, ...] = ("paper", "close", "near-collinear", "baseline-plane", "similar-elevation", "swarm", "leo")
DEFAULT_TARGETS = {
    "paper": 5,
    "close": 6,
    "near-collinear": 5,
    "baseline-plane": 5,
    "similar-elevation": 5,
    "swarm": 100,
    "leo": 10,
}


@dataclass(frozen=True)
class SceneGeometry:
    """Stations and true positions ``p_job_m`` (frames, K, 3) at times ``t_s`` (frames,)."""

    frame: Literal["local_enu", "ecef"]
    stations: tuple[Station, Station]
    t_s: FloatArray
    p_job_m: FloatArray
    sigma_deg: float
    focal_plane: bool  # σ is on the sky: the azimuth σ is σ / cos(el)


def build_scene(name: str, rng: np.random.Generator, targets: int, frames: int = 10) -> SceneGeometry:
    """Draw one scene by name (see ``SCENES``)."""
    if name not in SCENES:
        raise ValueError(f"unknown scene {name!r}; one of {', '.join(SCENES)}")
    if name == "leo":
        return _leo(rng, targets, frames)
    return _LOCAL[name](rng, targets, frames)


def _local_station(sid: str, p: FloatArray, sigma_deg: float) -> Station:
    s = np.radians(sigma_deg)
    return Station(sid, np.asarray(p, dtype=float), np.eye(3), s, s)


def _paper_stations(
    rng: np.random.Generator, sigma_deg: float, *, length_m: tuple[float, float] = (800.0, 1500.0), dz_m: float = 20.0
) -> tuple[tuple[Station, Station], FloatArray, FloatArray, FloatArray]:
    """S1 at the origin, S2 at a random heading; returns stations, midpoint, baseline and
    horizontal-normal unit vectors."""
    heading = rng.uniform(-np.pi, np.pi)
    length = rng.uniform(*length_m)
    s2 = np.array([length * np.sin(heading), length * np.cos(heading), rng.uniform(-dz_m, dz_m)])
    stations = (_local_station("S1", np.zeros(3), sigma_deg), _local_station("S2", s2, sigma_deg))
    b = s2 / np.linalg.norm(s2)
    normal = np.array([np.cos(heading), -np.sin(heading), 0.0]) * rng.choice([-1.0, 1.0])
    return stations, 0.5 * s2, b, normal


def _times(frames: int, dt_s: float) -> FloatArray:
    return np.arange(frames, dtype=np.float64) * dt_s


def _move(p_mid: FloatArray, v: FloatArray, t_s: FloatArray) -> FloatArray:
    """Straight flight through ``p_mid`` (K, 3) at mid-window with velocity ``v`` (K, 3)."""
    tau = t_s - 0.5 * (t_s[0] + t_s[-1])
    return p_mid[None, :, :] + tau[:, None, None] * v[None, :, :]


def _rotate_about_up(v: FloatArray, angle_rad: float) -> FloatArray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2]])


def _random_unit(rng: np.random.Generator, k: int) -> FloatArray:
    v = rng.normal(size=(k, 3))
    return np.asarray(v / np.linalg.norm(v, axis=1, keepdims=True))


def _spaced_ball(rng: np.random.Generator, k: int, radius_m: float, min_gap_m: float) -> FloatArray:
    """k points uniform in a ball, at least ``min_gap_m`` apart (rejection)."""
    pts: list[FloatArray] = []
    while len(pts) < k:
        q = _random_unit(rng, 1)[0] * radius_m * rng.uniform() ** (1 / 3)
        if all(np.linalg.norm(q - p) >= min_gap_m for p in pts):
            pts.append(q)
    return np.array(pts)


def _paper(rng: np.random.Generator, k: int, frames: int) -> SceneGeometry:
    stations, mid, _, normal = _paper_stations(rng, 0.02)
    horiz = _rotate_about_up(normal, np.radians(rng.uniform(-50, 50)))
    el = np.radians(rng.uniform(10, 40))
    centre = mid + 1500.0 * (np.cos(el) * horiz + np.array([0, 0, np.sin(el)]))
    p_mid = centre + _spaced_ball(rng, k, 15.0 * k ** (1 / 3), 3.0)
    v = _random_unit(rng, 1) * rng.uniform(20, 60) + rng.normal(0.0, 1.0, size=(k, 3))
    t = _times(frames, 0.1)
    return SceneGeometry("local_enu", stations, t, _move(p_mid, v, t), 0.02, False)


def _close(rng: np.random.Generator, k: int, frames: int) -> SceneGeometry:
    stations, mid, _, normal = _paper_stations(rng, 0.02)
    horiz = _rotate_about_up(normal, np.radians(rng.uniform(-50, 50)))
    el = np.radians(rng.uniform(10, 40))
    centre = mid + 1500.0 * (np.cos(el) * horiz + np.array([0, 0, np.sin(el)]))
    sizes: list[int] = []
    while sum(sizes) < k:
        sizes.append(min(int(rng.choice([2, 3])), k - sum(sizes)))
    group_centres = _spaced_ball(rng, len(sizes), 40.0 * len(sizes) ** (1 / 3), 30.0)
    pts, vel = [], []
    v_common = _random_unit(rng, 1)[0] * rng.uniform(20, 60)
    for c, size in zip(group_centres, sizes, strict=True):
        members = [c]
        while len(members) < size:
            q = members[int(rng.integers(len(members)))] + _random_unit(rng, 1)[0] * rng.uniform(2, 6)
            if all(np.linalg.norm(q - m) >= 2.0 for m in members):
                members.append(q)
        v_group = v_common + rng.normal(0.0, 2.0, size=3)
        pts.extend(members)
        vel.extend(v_group + rng.normal(0.0, 0.2, size=(size, 3)))
    t = _times(frames, 0.1)
    return SceneGeometry("local_enu", stations, t, _move(centre + np.array(pts), np.array(vel), t), 0.02, False)


def _near_collinear(rng: np.random.Generator, k: int, frames: int) -> SceneGeometry:
    stations, mid, b, _ = _paper_stations(rng, 0.02)
    b = b * rng.choice([-1.0, 1.0])
    e1 = np.array([0.0, 0.0, 1.0]) - b[2] * b
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(b, e1)
    pts: list[FloatArray] = []
    while len(pts) < k:
        off, roll, r = np.radians(rng.uniform(2, 6)), rng.uniform(0, np.pi), rng.uniform(1500, 3000)
        d = np.cos(off) * b + np.sin(off) * (np.cos(roll) * e1 + np.sin(roll) * e2)
        q = mid + r * d
        if all(np.linalg.norm(q - p) >= 3.0 for p in pts):
            pts.append(q)
    v = _random_unit(rng, k) * rng.uniform(20, 60, size=(k, 1))
    t = _times(frames, 0.1)
    return SceneGeometry("local_enu", stations, t, _move(np.array(pts), v, t), 0.02, False)


def _baseline_plane(rng: np.random.Generator, k: int, frames: int) -> SceneGeometry:
    stations, mid, b, normal = _paper_stations(rng, 0.02)
    bh = np.array([b[0], b[1], 0.0]) / np.hypot(b[0], b[1]) * rng.choice([-1.0, 1.0])
    up = np.array([0.0, 0.0, 1.0])
    offsets: list[float] = []
    while len(offsets) < k:
        o = rng.uniform(-1.0, 1.0)
        if all(abs(o - x) >= 0.25 for x in offsets) or k > 9:
            offsets.append(o)
    pts = []
    for o in offsets:
        el = np.radians(rng.uniform(40, 80))
        d_plane = np.cos(el) * bh + np.sin(el) * up
        d = np.cos(np.radians(o)) * d_plane + np.sin(np.radians(o)) * normal
        pts.append(mid + rng.uniform(1200, 2000) * d)
    in_plane = rng.normal(size=(k, 2))
    in_plane /= np.linalg.norm(in_plane, axis=1, keepdims=True)
    speed = rng.uniform(20, 60, size=(k, 1))
    v = speed * (in_plane[:, :1] * bh + in_plane[:, 1:] * up) + rng.normal(0, 0.3, size=(k, 1)) * normal
    t = _times(frames, 0.1)
    return SceneGeometry("local_enu", stations, t, _move(np.array(pts), v, t), 0.02, False)


def _similar_elevation(rng: np.random.Generator, k: int, frames: int) -> SceneGeometry:
    stations, mid, b, normal = _paper_stations(rng, 0.02, dz_m=0.0)
    el, r = np.radians(rng.uniform(15, 40)), rng.uniform(1200, 2000)
    toward = np.cos(el) * normal + np.array([0.0, 0.0, np.sin(el)])
    centre = mid + r * toward
    plane_normal = np.cross(b, toward)
    plane_normal /= np.linalg.norm(plane_normal)
    xs: list[float] = []
    while len(xs) < k:
        x = rng.uniform(-40.0 * k, 40.0 * k)
        if all(abs(x - y) >= 20.0 for y in xs):
            xs.append(x)
    p_mid = centre + np.outer(xs, b)
    out_of_plane = rng.uniform(1, 4, size=(k, 1)) * rng.choice([-1.0, 1.0], size=(k, 1))
    v = rng.uniform(20, 60) * b * rng.choice([-1.0, 1.0]) + out_of_plane * plane_normal
    t = _times(frames, 0.1)
    return SceneGeometry("local_enu", stations, t, _move(p_mid, v, t), 0.02, False)


def _swarm(rng: np.random.Generator, k: int, frames: int) -> SceneGeometry:
    stations, mid, _, normal = _paper_stations(rng, 0.005, length_m=(1000.0, 2000.0))
    az = np.radians(rng.uniform(-60, 60, size=k))
    el = np.radians(rng.uniform(10, 60, size=k))
    r = rng.uniform(2000, 6000, size=k)
    horiz = np.array([_rotate_about_up(normal, a) for a in az])
    d = np.cos(el)[:, None] * horiz + np.sin(el)[:, None] * np.array([0.0, 0.0, 1.0])
    v = _random_unit(rng, k) * rng.uniform(10, 80, size=(k, 1))
    t = _times(frames, 0.1)
    return SceneGeometry("local_enu", stations, t, _move(mid + r[:, None] * d, v, t), 0.005, False)


def _leo(rng: np.random.Generator, k: int, frames: int) -> SceneGeometry:
    import pymap3d.vincenty

    sigma_deg = 0.001
    lat1, lon1, h1 = 34.27, 108.95, 400.0
    lat2, lon2 = pymap3d.vincenty.vreckon(lat1, lon1, rng.uniform(200e3, 600e3), rng.uniform(0, 360))
    lat2, lon2 = float(lat2), float(lon2)
    h2 = rng.uniform(0.0, 1500.0)
    stations = tuple(
        Station(
            sid,
            geodetic_to_ecef(lat, lon, h),
            R_ecef_from_enu(lat, lon),
            np.radians(sigma_deg),
            np.radians(sigma_deg),
            0.0,
            (lat, lon, h),
        )
        for sid, lat, lon, h in (("S1", lat1, lon1, h1), ("S2", lat2, lon2, h2))
    )
    st = (stations[0], stations[1])
    t = _times(frames, 1.0)
    tau = t - 0.5 * (t[0] + t[-1])
    lat_c, lon_c = 0.5 * (lat1 + lat2), 0.5 * (lon1 + lon2)
    tracks: list[FloatArray] = []
    while len(tracks) < k:
        alt = rng.uniform(400e3, 1500e3)
        p0 = geodetic_to_ecef(lat_c + rng.uniform(-8, 8), lon_c + rng.uniform(-10, 10), alt)
        radius = float(np.linalg.norm(p0))
        along = np.cross(p0, _random_unit(rng, 1)[0])
        along /= np.linalg.norm(along)
        n = np.sqrt(MU_EARTH_M3_S2 / radius**3)
        # Circular orbit in the inertial frame that coincides with ECEF at mid-window.
        p_eci = np.cos(n * tau)[:, None] * p0 + radius * np.sin(n * tau)[:, None] * along
        c, s = np.cos(OMEGA_EARTH_RAD_S * tau), np.sin(OMEGA_EARTH_RAD_S * tau)
        p_ecef = np.stack([c * p_eci[:, 0] + s * p_eci[:, 1], -s * p_eci[:, 0] + c * p_eci[:, 1], p_eci[:, 2]], 1)
        if all(np.degrees(bearings_of(p_ecef, station)[1]).min() >= 20.0 for station in st):
            tracks.append(p_ecef)
    return SceneGeometry("ecef", st, t, np.stack(tracks, axis=1), sigma_deg, True)


_LOCAL: dict[str, Callable[[np.random.Generator, int, int], SceneGeometry]] = {
    "paper": _paper,
    "close": _close,
    "near-collinear": _near_collinear,
    "baseline-plane": _baseline_plane,
    "similar-elevation": _similar_elevation,
    "swarm": _swarm,
}

__all__ = ["DEFAULT_TARGETS", "SCENES", "SceneGeometry", "build_scene", "unit_vectors"]
