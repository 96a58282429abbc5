"""The panel axis from one image: the recipe.

1. Segment the target (its box, elongation and tip width; degenerate views refused).
2. LSD on the grayscale image; each segment refined to sub-pixel points and a line with its σ.
3. Group the lines' back-projected planes into families of parallel 3D lines (RANSAC).
4. The axis family is the longest one along the target's elongation; its direction is the
   weighted least-squares null direction of its planes (IRLS), with a covariance.
5. The axis is refitted with the families orthogonal to it. The wing's short edges (ends and gaps),
   grouped by their angle about the axis, give the short axis L″ fitted ⟂ the axis (a panel frame,
   orthogonal by construction), the panel normal, and Table 2's check from their own fit.
6. Perspective SNR: under the threshold the view is weak perspective, answered with the IPPE
   mirror pair from one wing's corners (a root hidden behind the bus derived from the tip and the
   prior) and the panel prior, or with the in-image angle alone.
7. Frames: camera -> station ENU -> ECEF, pitch/yaw by eq. 1, σ propagated.
"""

from __future__ import annotations

import time

import numpy as np

from .._typing import FloatArray, Progress, no_progress
from ..imaging.camera import PinholeCamera
from .axis import (
    DirectionFit,
    PlaneObs,
    angle_between_lines_deg,
    fit_direction,
    with_edge_bias,
)
from .edges import Edge, Family, find_edges, group_families
from .errors import DegenerateViewError, DepthUnobservableError, TooFewEdgesError
from .frame_fit import fit_about_axis, fit_panel_frame
from .meta import PanelAxisInput
from .options import EstimateOptions
from .outputs import Frames
from .panel_block import panel_block
from .paper import estimate_paper
from .result import Axis, Candidate, Observability, Panel, PanelAxisResult, Segmentation
from .segment import Target, find_target
from .short_family import short_family
from .weak import best_wing, hidden_root_corners, ippe_candidates, wing_corners

MIN_ELONGATION = 2.0  # under it no wing is seen along the axis (end-on, or edge-on and unlit)
MIN_TIP_WIDTH_PX = 4.0  # under it the panel is seen edge-on
MIN_AXIS_EXTENT_PX = 30.0
MAX_CORNER_FIT_PX = 1.0  # IPPE reprojection rms over which the wing's corners are doubtful
ELONGATION_ALIGN_DEG = 20.0


def estimate_axis(
    gray: FloatArray,
    meta: PanelAxisInput,
    options: EstimateOptions | None = None,
    progress: Progress = no_progress,
    *,
    full_scale: float | None = None,
) -> PanelAxisResult:
    """Estimate the panel axis from a grayscale image (DN, float (H, W)) and its validated meta.json;
    ``full_scale`` is the image's saturation level (default: 255, or 65535 when a pixel is over 255)."""
    options = options or EstimateOptions()
    t0 = time.perf_counter()
    camera = meta.pinhole
    frames = Frames(meta)
    if full_scale is None:
        full_scale = 255.0 if gray.max() <= 255 else 65535.0
    if options.method == "paper":
        return _paper_result(gray, camera, frames, options, t0)
    rng = np.random.default_rng(options.seed)
    # 1. The target region, and the views no edge can save.
    progress("segment", 0.1)
    target = find_target(gray, full_scale)
    if target.elongation < MIN_ELONGATION:
        raise DegenerateViewError(
            f"image: the target is not elongated (ratio {target.elongation:.2f}, {MIN_ELONGATION} needed): no wing is "
            "seen along its axis (an end-on or edge-on view)",
            field="image",
        )
    if target.tip_width_px < MIN_TIP_WIDTH_PX:
        raise DegenerateViewError(
            f"image: the wings are {target.tip_width_px:.1f} px wide: the panel is seen edge-on", field="image"
        )
    # 2. Sub-pixel edges on the grayscale image.
    progress("edges", 0.3)
    edges = find_edges(gray, target, camera)
    long_edges = [e for e in edges if e.length_px >= options.min_line_px]
    if len(long_edges) < 2:
        raise TooFewEdgesError(
            f"image: {len(long_edges)} straight edges of {options.min_line_px:.0f} px or more (2 needed)", field="image"
        )
    # 3-4. Families of parallel lines; the axis family and its direction.
    progress("families", 0.5)
    families = group_families(edges, camera)
    axis_family = _axis_family(families, target, options.min_line_px)
    if axis_family is None:
        raise TooFewEdgesError("image: no two long edges share a 3D direction along the target", field="image")
    extent = _extent(axis_family)
    if extent < MIN_AXIS_EXTENT_PX:
        raise DegenerateViewError(f"image: the projected axis is {extent:.0f} px long (30 px needed)", field="image")
    axis_planes = [e.plane for e in axis_family.edges]
    fit = fit_direction(axis_planes)
    # 5. The panel frame. The axis is refitted with the families found orthogonal to it (bus edges
    # across it; they also expose a biased axis edge). The wing's short edges are then found about
    # that axis, and when their own fit is orthogonal to it within σ, the short axis is fitted with
    # the axis held (orthogonal to it by construction). The Table 2 check is between that axis and the
    # short edges' own fit.
    orthogonal = _orthogonal_families(families, axis_family, fit)
    if orthogonal:
        fit = fit_panel_frame(fit, axis_planes, orthogonal).axis
    separate = fit
    short = short_family(edges, axis_family, fit.direction)
    fit = with_edge_bias(fit, axis_planes, [e.line.half_length_px for e in axis_family.edges])
    # 6. Perspective SNR and the answer it allows.
    progress("axis", 0.8)
    a_img = axis_family.image_direction()
    snr = _perspective_snr(axis_family, a_img, camera)
    weak = snr < options.weak_snr
    # In weak perspective every edge plane holds the line of sight: the panel block gives the short
    # edges only, so their fits are not made.
    short_fit, constrained = None, None
    if short is not None and not weak:
        short_fit = fit_direction([e.plane for e in short.edges], reject=True)
        if _orthogonal_within_sigma(separate, short_fit):
            constrained = fit_about_axis(fit, short_fit, [e.plane for e in short.edges])
    plane_normal = _axis_plane_normal(axis_family, a_img, camera)
    warnings = []
    if target.touches_border:
        warnings.append("target_touches_border")
    if target.saturated_px > 0.005 * target.target_px:
        warnings.append("saturated")
    candidates: list[Candidate] = []
    corners = None
    if weak:
        warnings.append("weak_perspective")
        axis, candidates, corners = _weak_answer(
            meta, axis_family, edges, target, camera, frames, rng, options, warnings
        )
    else:
        axis = frames.axis(fit.direction, fit.cov_tangent_rad2, fit.basis)
    image_angle = float(np.degrees(np.arctan2(a_img[1], a_img[0])) % 180.0)
    # 7. The result.
    tilt, sigma_tilt = _tilt(fit, camera, axis_family) if not weak else (None, None)
    return PanelAxisResult(
        method="ours",
        axis=axis,
        ambiguous=weak,
        candidates=candidates,
        image_angle_deg=image_angle,
        sigma_image_angle_deg=_sigma_image_angle_deg(axis_family),
        axis_plane_normal=frames.direction(plane_normal),
        observability=Observability(
            regime="weak_perspective" if weak else "perspective",
            perspective_snr=snr,
            tilt_deg=tilt,
            sigma_tilt_deg=sigma_tilt,
        ),
        panel=panel_block(fit, separate, axis_family, short, short_fit, constrained, frames, corners, weak=weak),
        segmentation=Segmentation(
            threshold=target.threshold,
            target_px=target.target_px,
            bbox_px=list(target.bbox_px),
            elongation=target.elongation,
            tip_width_px=target.tip_width_px,
        ),
        warnings=warnings,
        timings_ms={"total": 1000 * (time.perf_counter() - t0)},
    )


def _axis_family(families: list[Family], target: Target, min_line_px: float) -> Family | None:
    """The family with the most edge length along the target's elongation (2+ edges, one long)."""
    best, best_score = None, 0.0
    for fam in families:
        if len(fam.edges) < 2 or max(e.length_px for e in fam.edges) < min_line_px:
            continue
        score = sum(
            e.length_px
            for e in fam.edges
            if abs(e.line.direction @ target.direction) > np.cos(np.radians(ELONGATION_ALIGN_DEG))
        )
        if score > best_score:
            best, best_score = fam, score
    return best


def _extent(family: Family) -> float:
    a = family.image_direction()
    s = np.array([a @ p for e in family.edges for p in e.line.endpoints_px])
    return float(np.ptp(s))


def _orthogonal_within_sigma(fit: DirectionFit, other: DirectionFit) -> bool:
    """Whether two separately fitted directions are orthogonal within 3σ (both fits) plus 0.5° (an
    allowance for edge-model bias, which the fits' σ do not hold)."""
    tol = np.radians(0.5) + 3 * np.hypot(fit.sigma_rad, other.sigma_rad)
    return bool(abs(float(other.direction @ fit.direction)) < np.sin(tol))


def _orthogonal_families(
    families: list[Family], axis_family: Family, fit: DirectionFit
) -> list[tuple[DirectionFit, list[PlaneObs]]]:
    """Families of 3+ edges (two edges always fit a direction exactly, so a pair cannot show it is
    a family) orthogonal to the axis within σ (``_orthogonal_within_sigma``), each with its
    separate fit and its edges' planes."""
    out = []
    for fam in families:
        if fam is axis_family or len(fam.edges) < 3:
            continue
        planes = [e.plane for e in fam.edges]
        f2 = fit_direction(planes)
        if _orthogonal_within_sigma(fit, f2):
            out.append((f2, planes))
    return out


def _perspective_snr(family: Family, a_img: FloatArray, camera: PinholeCamera) -> float:
    """(largest separation of the family's lines / f) / the angle σ of its two best-measured lines
    (those carry the depth information; short or ragged members would only dilute it)."""
    b = np.array([-a_img[1], a_img[0]])
    offsets = np.array([b @ e.line.centroid_px for e in family.edges])
    sep = float(np.ptp(offsets))
    var = np.sort([e.line.var_angle_rad2 for e in family.edges])[:2]
    sig = float(np.sqrt(var.mean()))
    return (sep / camera.focal_px) / max(sig, 1e-12)


def _axis_plane_normal(family: Family, a_img: FloatArray, camera: PinholeCamera) -> FloatArray:
    """The plane {line of sight, axis}: through the camera and the family's mean image line."""
    w = np.array([e.length_px for e in family.edges])
    c = (w[:, None] * np.array([e.line.centroid_px for e in family.edges])).sum(axis=0) / w.sum()
    n2 = np.array([-a_img[1], a_img[0]])
    return camera.plane_normal(np.array([n2[0], n2[1], -n2 @ c]))


def _sigma_image_angle_deg(family: Family) -> float:
    info = sum(1.0 / max(e.line.var_angle_rad2, 1e-18) for e in family.edges)
    return float(np.degrees(np.sqrt(1.0 / info)))


def _tilt(fit: DirectionFit, camera: PinholeCamera, family: Family) -> tuple[float, float]:
    """The axis's angle out of the plane ⟂ the line of sight (deg) and its σ."""
    w = np.array([e.length_px for e in family.edges])
    c = (w[:, None] * np.array([e.line.centroid_px for e in family.edges])).sum(axis=0) / w.sum()
    los = camera.rays(c)[0]
    d = fit.direction
    tilt = float(np.degrees(np.arcsin(min(1.0, abs(float(d @ los))))))
    g = los - (d @ los) * d  # gradient of d·los on the sphere
    gt = fit.basis @ g
    var = float(gt @ fit.cov_tangent_rad2 @ gt) / max(1e-12, 1 - (d @ los) ** 2)
    return tilt, float(np.degrees(np.sqrt(max(var, 0.0))))


def _weak_answer(
    meta: PanelAxisInput,
    family: Family,
    edges: list[Edge],
    target: Target,
    camera: PinholeCamera,
    frames: Frames,
    rng: np.random.Generator,
    options: EstimateOptions,
    warnings: list[str],
) -> tuple[Axis | None, list[Candidate], FloatArray | None]:
    """Weak perspective: the IPPE pair with the prior, else no axis (or a refusal)."""
    if not meta.prior_complete:
        if options.require_axis:
            raise DepthUnobservableError(
                "prior: weak perspective (the edges' planes meet at the line of sight): the axis's tilt needs "
                "prior.panel_length_m and prior.panel_width_m",
                field="prior",
            )
        return None, [], None
    assert meta.prior is not None and meta.prior.panel_length_m is not None and meta.prior.panel_width_m is not None
    L, W = meta.prior.panel_length_m, meta.prior.panel_width_m
    range_m = meta.prior.range_m
    found = best_wing(wing_corners(family, edges), L, W, camera, range_m)
    if found is None and range_m is not None:
        # A wing's root is often hidden behind the bus: its corners then come from the tip's and the
        # prior. Tried only when no set of four seen corners fits: near a face-on short edge the
        # derived root is sensitive to the tip's width, and a seen root is better.
        hidden = hidden_root_corners(family, edges, target.mask, L, W, camera.focal_px / range_m)
        found = best_wing(hidden, L, W, camera, range_m)
    if found is None:
        if options.require_axis:
            raise DepthUnobservableError(
                "image: weak perspective and no wing's four corners fit the panel prior", field="image"
            )
        warnings.append("wing_corners_not_found")
        return None, [], None
    corner_set, fit_px = found
    corners = corner_set.corners_px
    if fit_px > MAX_CORNER_FIT_PX:
        warnings.append("wing_corners_misfit")
    if corner_set.rebuild is not None:
        warnings.append("wing_root_hidden")
    # A rectangle that fits the corners worse than their noise says the corners are off by about
    # that much: the Monte Carlo uses the larger of the two.
    poses = ippe_candidates(corner_set, L, W, camera, max(corner_set.sigma_px, fit_px), rng)
    if not poses:
        return None, [], corners
    cands = []
    for k, pose in enumerate(poses[:2]):
        a = frames.axis(pose.axis_cam, pose.cov_tangent_rad2, pose.basis)
        cands.append(
            Candidate(
                kind="primary" if k == 0 else "mirror",
                camera=a.camera,
                station_enu=a.station_enu,
                ecef=a.ecef,
                cost=pose.cost_px,
                sigma_deg=a.sigma_deg,
                pitch_deg=a.pitch_deg,
                yaw_deg=a.yaw_deg,
                sigma_pitch_deg=a.sigma_pitch_deg,
                sigma_yaw_deg=a.sigma_yaw_deg,
            )
        )
    best = poses[0]
    return frames.axis(best.axis_cam, best.cov_tangent_rad2, best.basis), cands, corners


def _paper_result(
    gray: FloatArray, camera: PinholeCamera, frames: Frames, options: EstimateOptions, t0: float
) -> PanelAxisResult:
    """The paper's pipeline as a result: the axis without σ, its two edges, L″ when found."""
    pf = estimate_paper(gray, camera, options.min_line_px)
    axis = frames.axis(pf.axis_cam, np.zeros((2, 2)), np.zeros((2, 3)))
    axis.sigma_deg = axis.sigma_pitch_deg = axis.sigma_yaw_deg = None
    axis.cov_tangent_rad2 = axis.tangent_basis_enu = axis.tangent_basis_camera = None
    seg = pf.edges_px[0]  # the longest edge gives the in-image angle
    a_img = (seg[2:] - seg[:2]) / np.linalg.norm(seg[2:] - seg[:2])
    mid = (pf.edges_px[:, :2] + pf.edges_px[:, 2:]).mean(axis=0) / 2
    n2 = np.array([-a_img[1], a_img[0]])
    panel = Panel(edges_px=pf.edges_px.tolist(), long_edges=2)
    if pf.short_cam is not None:
        panel.short_axis = frames.direction(pf.short_cam)
        panel.orthogonality_deg = abs(90.0 - angle_between_lines_deg(pf.axis_cam, pf.short_cam))
    return PanelAxisResult(
        method="paper",
        axis=axis,
        ambiguous=False,
        image_angle_deg=float(np.degrees(np.arctan2(a_img[1], a_img[0])) % 180.0),
        axis_plane_normal=frames.direction(camera.plane_normal(np.array([n2[0], n2[1], -n2 @ mid]))),
        observability=Observability(regime="perspective"),
        panel=panel,
        segmentation=Segmentation(threshold=pf.threshold, target_px=pf.target_px),
        timings_ms={"total": 1000 * (time.perf_counter() - t0)},
    )
