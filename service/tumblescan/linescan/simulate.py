"""Line-scan lidar simulator (method.md section 7): corner tracks and dense frames.

The target is static in its body frame and the rays move: for the line taken at ``t``,
the ray origin and directions are mapped into the target's reference-time pose with the
inverse motion, all rays of all frames are cast in one batch against the mesh, and each hit
is mapped back to the sensor frame at its own time before noise is added.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field

from .._open3d import load_open3d
from ..target.motion import Motion, apply_rotation
from ..target.shape import SatelliteShape
from ..target.shapes import Shape
from .sensor import Scanner, azimuth_elevation
from .tracks import Tracks

# A corner counts as visible when the first surface along its ray is no nearer than this.
OCCLUSION_TOLERANCE_M = 0.01


class Scene(BaseModel):
    """What the simulator observes: scanner, target shape and pose, number of frames."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    scanner: Scanner = Scanner()
    shape: Shape = SatelliteShape()
    frames: int = Field(15, ge=1, le=1000)
    start_s: float = Field(0.0, allow_inf_nan=False, description="time of the first line")
    body_offset_m: tuple[float, float, float] = Field(
        (0.0, 0.0, 0.0), description="bus centre minus the precession centre at the reference time"
    )
    R_body_to_sensor: tuple[tuple[float, float, float], ...] = ((1, 0, 0), (0, 1, 0), (0, 0, 1))
    noise: bool = True
    occlusion: bool = True

    def body_points(self, motion: Motion, points_body_m: NDArray[np.float64]) -> NDArray[np.float64]:
        """Body-frame points placed at their reference-time position in the sensor frame."""
        R = np.asarray(self.R_body_to_sensor, dtype=float)
        origin = np.asarray(motion.center_m) + np.asarray(self.body_offset_m)
        return np.asarray(points_body_m @ R.T + origin, dtype=float)


@dataclass(frozen=True)
class FrameCloud:
    """Dense points of simulated frames with per-point time, frame, line and pixel.

    xyz_m: ``(n, 3)`` observed (noisy) positions; xyz_true_m: the same without noise;
    reference_m: ``(n, 3)`` true position of each hit at the reference time (the
    undistorted cloud).
    """

    xyz_m: NDArray[np.float64]
    t_s: NDArray[np.float64]
    frame: NDArray[np.int32]
    line: NDArray[np.int32]
    pixel: NDArray[np.int32]
    xyz_true_m: NDArray[np.float64]
    reference_m: NDArray[np.float64]


@dataclass(frozen=True)
class TrackTruth:
    """Ground truth of simulated tracks: each observation's noise-free position and the
    corners' positions at the reference time."""

    xyz_true_m: NDArray[np.float64]
    corners_reference_m: NDArray[np.float64]


def random_motion(
    rng: np.random.Generator,
    *,
    distance_m: float = 50.0,
    spin_rate_deg_s: tuple[float, float] = (15.0, 37.0),
    precession_rate_deg_s: tuple[float, float] = (3.0, 14.0),
    min_nutation_deg: float = 10.0,
    reference_time_s: float = 0.0,
) -> Motion:
    """A motion on the paper's grid: uniform rates, random axes at least ``min_nutation_deg``
    apart (and from anti-parallel), precession centre on the boresight at ``distance_m``."""
    while True:
        axes = rng.normal(size=(2, 3))
        axes /= np.linalg.norm(axes, axis=1, keepdims=True)
        nutation = np.degrees(np.arccos(np.clip(axes[0] @ axes[1], -1, 1)))
        if min_nutation_deg <= nutation <= 180 - min_nutation_deg:
            break
    return Motion.from_degrees(
        spin_axis=axes[0],
        spin_rate_deg_s=float(rng.uniform(*spin_rate_deg_s)),
        precession_axis=axes[1],
        precession_rate_deg_s=float(rng.uniform(*precession_rate_deg_s)),
        center_m=(0.0, 0.0, distance_m),
        reference_time_s=reference_time_s,
    )


def simulate_tracks(motion: Motion, scene: Scene, *, seed: int | None = 0) -> tuple[Tracks, TrackTruth]:
    """Observe the target's corners once per frame, at the time of the line crossing each.

    A corner is observed in frame ``f`` at the first line ``k`` whose azimuth bin reaches
    the corner's azimuth at that line's time ``t_fk``, if the corner was not already behind
    the first line, its elevation is in the field of view and (with ``scene.occlusion``) no
    surface hides it. Missing corners stay missing.
    """
    rng = np.random.default_rng(seed)
    sc = scene.scanner
    corners = scene.body_points(motion, scene.shape.corners_m())
    times = sc.line_times_s(scene.frames, scene.start_s)  # (F, L)
    # Corner positions at every line time: (F, L, C, 3).
    flat_t = np.repeat(times.ravel(), len(corners))
    flat_p = np.tile(corners, (times.size, 1))
    pos = motion.position(flat_p, flat_t).reshape(*times.shape, len(corners), 3)
    az, el = azimuth_elevation(pos)
    half = np.radians(sc.fov_azimuth_deg) / sc.lines / 2
    # The sweep reaches the corner at the first line whose bin end passes it; a corner
    # already behind the first line's bin (or never reached) is outside the field of view.
    gap = sc.azimuths_rad()[None, :, None] + half - az  # (F, L, C)
    reached = gap >= 0
    line = np.argmax(reached, axis=1)  # (F, C)
    f_all, c_all = np.indices(line.shape)
    first_gap = gap[f_all, line, c_all]
    el_at = el[f_all, line, c_all]
    behind = (line == 0) & (first_gap > 2 * half)
    seen = reached.any(axis=1) & ~behind & (np.abs(el_at) <= np.radians(sc.fov_elevation_deg) / 2)
    f_idx, c_idx = np.nonzero(seen)
    k_idx = line[f_idx, c_idx]
    t_obs = times[f_idx, k_idx]
    p_true = pos[f_idx, k_idx, c_idx]
    if scene.occlusion:
        visible = _unoccluded(motion, scene, p_true, t_obs)
        f_idx, c_idx, t_obs, p_true = f_idx[visible], c_idx[visible], t_obs[visible], p_true[visible]
    # A corner seen in one frame only is no track; a feature tracker would not report it.
    counts = np.bincount(c_idx, minlength=len(corners))
    tracked = counts[c_idx] >= 2
    f_idx, c_idx, t_obs, p_true = f_idx[tracked], c_idx[tracked], t_obs[tracked], p_true[tracked]
    p_obs = sc.noise.sample(p_true, rng) if scene.noise else p_true.copy()
    names = np.array([f"c{i + 1}" for i in range(len(corners))])[c_idx]
    tracks = Tracks.from_arrays(names, t_obs, p_obs, frame=f_idx, sensor=sc.noise)
    # Tracks sorts by (frame, time); reorder the truth the same way.
    order = np.lexsort((t_obs, f_idx))
    return tracks, TrackTruth(xyz_true_m=p_true[order], corners_reference_m=corners)


def _unoccluded(motion: Motion, scene: Scene, p_m: NDArray[np.float64], t_s: NDArray[np.float64]) -> NDArray[np.bool_]:
    rng_m = np.linalg.norm(p_m, axis=1)
    hit_m = _cast(motion, scene, t_s, p_m / rng_m[:, None])
    return np.asarray(hit_m >= rng_m - OCCLUSION_TOLERANCE_M)


def _cast(
    motion: Motion, scene: Scene, t_s: NDArray[np.float64], dir_sensor: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Distance to the first hit of rays from the sensor origin (inf where none)."""
    o3d = load_open3d()

    x = motion.params()
    tau = t_s - motion.reference_time_s
    origin_b, dir_b = _rays_to_reference(x, tau, dir_sensor)
    scene_rc = _raycasting_scene(motion, scene)
    rays = o3d.core.Tensor(np.hstack([origin_b, dir_b]).astype(np.float32))
    hit = scene_rc.cast_rays(rays, nthreads=0)["t_hit"].numpy().astype(float)
    return np.asarray(hit, dtype=float)


def _rays_to_reference(
    x: NDArray[np.float64], tau_s: NDArray[np.float64], dir_sensor: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    center = x[6:9]
    origin = center + apply_rotation(x, tau_s, np.broadcast_to(-center, dir_sensor.shape), inverse=True)
    direction = apply_rotation(x, tau_s, dir_sensor, inverse=True)
    return np.asarray(origin, dtype=float), np.asarray(direction, dtype=float)


def _raycasting_scene(motion: Motion, scene: Scene):  # type: ignore[no-untyped-def]
    o3d = load_open3d()

    mesh = scene.shape.mesh()
    verts = scene.body_points(motion, np.asarray(mesh.vertices))
    mesh.vertices = o3d.utility.Vector3dVector(verts)
    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    return rc


def simulate_frames(motion: Motion, scene: Scene, *, seed: int | None = 0) -> FrameCloud:
    """Cast every ray of every line of every frame; keep the hits (method.md section 7)."""
    o3d = load_open3d()

    rng = np.random.default_rng(seed)
    sc = scene.scanner
    times = sc.line_times_s(scene.frames, scene.start_s).ravel()  # (F*L,)
    dirs = sc.ray_directions()  # (L, P, 3)
    x = motion.params()
    tau = times - motion.reference_time_s
    # Per line: ray origin and the rotation taking sensor directions into the reference pose.
    origin_b = _rays_to_reference(x, tau, np.zeros((len(tau), 3)))[0]
    basis = np.broadcast_to(np.eye(3), (len(tau), 3, 3))
    R_sensor_to_ref = np.stack(
        [_rays_to_reference(x, tau, basis[:, :, i])[1] for i in range(3)], axis=-1
    )  # (F*L, 3, 3), columns are the images of the basis vectors
    lines_per_frame = sc.lines
    dir_b = np.einsum("fkij,kpj->fkpi", R_sensor_to_ref.reshape(scene.frames, lines_per_frame, 3, 3), dirs)
    n_pix = sc.pixels
    rays = np.empty((scene.frames, lines_per_frame, n_pix, 6), dtype=np.float32)
    rays[..., :3] = origin_b.reshape(scene.frames, lines_per_frame, 1, 3)
    rays[..., 3:] = dir_b
    hit = _raycasting_scene(motion, scene).cast_rays(o3d.core.Tensor(rays.reshape(-1, 6)), nthreads=0)
    t_hit = hit["t_hit"].numpy().astype(float)
    ok = np.isfinite(t_hit) & (t_hit <= sc.max_range_m)
    idx = np.flatnonzero(ok)
    f_i, rem = np.divmod(idx, lines_per_frame * n_pix)
    k_i, p_i = np.divmod(rem, n_pix)
    rng_m = t_hit[idx]
    xyz_true = dirs[k_i, p_i] * rng_m[:, None]
    line_row = f_i * lines_per_frame + k_i
    reference = origin_b[line_row] + np.einsum("nij,nj->ni", R_sensor_to_ref[line_row], dirs[k_i, p_i]) * rng_m[:, None]
    xyz = sc.noise.sample(xyz_true, rng) if scene.noise else xyz_true.copy()
    return FrameCloud(
        xyz_m=xyz,
        t_s=times[line_row],
        frame=f_i.astype(np.int32),
        line=k_i.astype(np.int32),
        pixel=p_i.astype(np.int32),
        xyz_true_m=xyz_true,
        reference_m=reference,
    )


__all__ = [
    "FrameCloud",
    "Scene",
    "TrackTruth",
    "random_motion",
    "simulate_frames",
    "simulate_tracks",
]
