"""The SE(3) pose graph in GTSAM: marker factors (known layout) or bearing-range factors with the
layout as landmarks (bootstrapped layout), an optional white-noise-acceleration (constant-velocity)
prior, Levenberg-Marquardt and marginal covariances.

Node conventions: marker factors use ``T_body_world`` nodes (GTSAM's known-landmark and
bearing-range factors see the body as the static map: the paper's SLAM duality); the motion prior
uses ``T_world_body`` nodes, so its twist is the body-frame twist, with each frame's marker fit
summarized as a pose prior (exact to second order for a known layout). Covariances are returned in
the contract's order (dtheta_world [rad], dp_world [m]).
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._typing import BoolArray, FloatArray, IntArray
from .geometry import skew

STATUS_MEASURED, STATUS_BRIDGED, STATUS_MISSING = "measured", "bridged", "missing"
WINDOW_S = 0.2  # window over which the motion prior's PSD is read from the per-frame poses


@dataclass
class GraphResult:
    R: FloatArray  # (F, 3, 3) R_world_body
    t: FloatArray  # (F, 3)
    cov: FloatArray  # (F, 6, 6), NaN where missing
    status: list[str]
    layout_m: FloatArray
    layout_sigma_m: FloatArray
    info: dict[str, Any] = field(default_factory=dict)


def no_poses(F: int) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(R (F, 3, 3), t (F, 3), cov (F, 6, 6)) all NaN: no frame has a pose yet."""
    return np.full((F, 3, 3), np.nan), np.full((F, 3), np.nan), np.full((F, 6, 6), np.nan)


def _noise(sigmas: FloatArray | float, dim: int, robust: str, k: float) -> Any:
    import gtsam

    base = (
        gtsam.noiseModel.Isotropic.Sigma(dim, sigmas)
        if isinstance(sigmas, float)
        else gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sigmas, dtype=float))
    )
    if robust == "huber":
        return gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(k), base)
    if robust == "cauchy":
        return gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Cauchy.Create(k), base)
    return base


def _pose(R: FloatArray, t: FloatArray) -> Any:
    import gtsam

    return gtsam.Pose3(gtsam.Rot3(np.asarray(R)), np.asarray(t, dtype=float))


def _solve(graph: Any, values: Any) -> tuple[Any, int, float]:
    import gtsam

    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(50)
    params.setRelativeErrorTol(1e-8)
    opt = gtsam.LevenbergMarquardtOptimizer(graph, values, params)
    result = opt.optimize()
    return result, int(opt.iterations()), 2.0 * float(graph.error(result))


class _QRMarginals:
    """``gtsam.Marginals`` by QR: the graph linearized at the solution and eliminated by
    Householder QR on the whitened Jacobian (COLAMD order), then each variable's marginal from the
    Bayes tree."""

    def __init__(self, graph: Any, values: Any) -> None:
        import gtsam

        linear = graph.linearize(values)
        self._tree = linear.eliminateMultifrontal(gtsam.Ordering.ColamdGaussianFactorGraph(linear), gtsam.EliminateQR)

    def marginalCovariance(self, key: int) -> FloatArray:  # gtsam.Marginals' name and signature
        return np.asarray(self._tree.marginalCovariance(key))


def solve_marginals(graph: Any, values: Any) -> Any:
    """The marginals of a solved graph: GTSAM's (Cholesky of the information matrix, the fast way),
    or by QR where Cholesky finds the system indeterminate. A stiff motion prior (a small PSD at a
    high frame rate) against precise poses, or a loose one against a stiff rotation, makes the
    information matrix singular to working precision while its square root, which QR factors, is
    still well conditioned (squaring doubles the condition number's exponent). LM solved it all the
    same (its damping regularizes); only the marginals need this."""
    import gtsam

    try:
        return gtsam.Marginals(graph, values)
    except RuntimeError as exc:
        if "Indeterminate" not in str(exc):
            raise
        return _QRMarginals(graph, values)


def markers_graph(
    xyz_m: FloatArray,
    obs_frame: IntArray,
    obs_marker: IntArray,
    measured: BoolArray,
    R0: FloatArray,
    t0: FloatArray,
    layout_m: FloatArray,
    sigma_m: float,
    *,
    estimate_layout: bool,
    gauge: tuple[int, int, int] | None,
    robust: str,
    robust_k: float,
    marginals: bool,
) -> GraphResult:
    """Poses of the measured frames (and the layout, if ``estimate_layout``) from every inlier marker.

    Cost: ``sum_k sum_m |T_world_body,k p_m - y_km|^2 / sigma^2`` over inlier observations
    (``obs_marker >= 0``) of measured frames. xyz_m (N, 3) world [m]; obs_frame (N,) frame index;
    obs_marker (N,) marker index or -1; measured (F,); R0, t0 (F, ...) initial poses; layout_m (M, 3)
    body [m]; gauge: with a layout to estimate, the three markers whose 3-2-1 coordinates are held
    (first: all three, third: y and z, second: z), which keeps the frame they define."""
    import gtsam
    from gtsam.symbol_shorthand import L, X

    started = time.perf_counter()
    F, M = len(measured), len(layout_m)
    use = (obs_marker >= 0) & measured[obs_frame]
    # Bearing-range factors need the world origin away from the points: shift it (undone below).
    shift = np.zeros(3)
    if estimate_layout:
        shift = np.array([0.0, 0.0, 20.0]) - xyz_m[use].mean(axis=0)
    y = xyz_m + shift
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    frames = np.flatnonzero(measured)
    for k in frames:
        values.insert(X(int(k)), _pose(R0[k], t0[k] + shift).inverse())
    iso = _noise(sigma_m, 3, robust, robust_k)
    for i in np.flatnonzero(use):
        fk, m = int(obs_frame[i]), int(obs_marker[i])
        if estimate_layout:
            r = float(np.linalg.norm(y[i]))
            nm = _noise(np.array([sigma_m / r, sigma_m / r, sigma_m]), 3, robust, robust_k)
            graph.add(gtsam.BearingRangeFactor3D(X(fk), L(m), gtsam.Unit3(y[i]), r, nm))
        else:
            graph.add(gtsam.KnownLandmarkFactorPose3(X(fk), layout_m[m], y[i], iso))
    if estimate_layout:
        assert gauge is not None
        for m in range(M):
            values.insert(L(m), layout_m[m])
        big, tiny = 1e3, 1e-7
        for m, sig in zip(gauge, ([tiny] * 3, [big, big, tiny], [big, tiny, tiny]), strict=True):
            graph.add(gtsam.PriorFactorPoint3(L(m), layout_m[m], gtsam.noiseModel.Diagonal.Sigmas(np.array(sig))))
    result, iterations, chi2 = _solve(graph, values)
    R, t, cov = no_poses(F)
    marg = solve_marginals(graph, result) if marginals else None
    for k in frames:
        T_wb = result.atPose3(X(int(k))).inverse()
        R[k], t[k] = T_wb.rotation().matrix(), T_wb.translation() - shift
        if marg is not None:
            cov[k] = _cov_from_body_world(marg.marginalCovariance(X(int(k))), t[k] + shift)
    lay = np.array([result.atPoint3(L(m)) for m in range(M)]) if estimate_layout else layout_m.copy()
    lay_sigma = np.zeros(M)
    if estimate_layout and marg is not None:
        lay_sigma = np.array([np.sqrt(np.trace(marg.marginalCovariance(L(m))) / 3.0) for m in range(M)])
    status = [STATUS_MEASURED if measured[k] else STATUS_MISSING for k in range(F)]
    n_obs = int(use.sum())
    info = {
        "nodes": len(frames),
        "landmarks": M,
        "factors": {"marker": n_obs, "motion": 0},
        "iterations": iterations,
        "chi2_final": chi2,
        "dof": 3 * n_obs - 6 * len(frames) - (3 * M - 6 if estimate_layout else 0),
        "solver": "gtsam LM",
        "time_s": time.perf_counter() - started,
    }
    return GraphResult(R, t, cov, status, lay, lay_sigma, info)


def _cov_from_body_world(C_xi: FloatArray, p_world_m: FloatArray) -> FloatArray:
    """A ``T_body_world`` marginal (right perturbation xi) as (dtheta_world, dp_world) of ``T_world_body``:
    ``T_wb,true = exp(-xi) T_wb``, so ``dtheta = -phi`` and ``dp = -rho + [p]x phi``."""
    A = np.zeros((6, 6))
    A[:3, :3] = -np.eye(3)
    A[3:, 3:] = -np.eye(3)
    A[3:, :3] = skew(p_world_m)
    return np.asarray(A @ C_xi @ A.T)


def frame_covariances(
    R: FloatArray, obs_frame: IntArray, obs_marker: IntArray, layout_m: FloatArray, sigma_m: float, measured: BoolArray
) -> FloatArray:
    """Per-frame Kabsch covariances ``sigma^2 (sum J^T J)^-1`` (F, 6, 6), order (dtheta_world, dp_world)."""
    F = len(measured)
    info = np.zeros((F, 6, 6))
    use = (obs_marker >= 0) & measured[obs_frame]
    k = obs_frame[use]
    q = np.einsum("nij,nj->ni", R[k], layout_m[obs_marker[use]])
    J = np.zeros((len(k), 3, 6))
    J[:, :, :3] = -skew(q)
    J[:, :, 3:] = np.eye(3)
    np.add.at(info, k, np.einsum("nai,naj->nij", J, J))
    cov = np.full((F, 6, 6), np.nan)
    cov[measured] = np.linalg.inv(info[measured]) * sigma_m**2
    return cov


def motion_graph(
    t_s: FloatArray,
    R: FloatArray,
    t: FloatArray,
    cov: FloatArray,
    measured: BoolArray,
    *,
    q_rot: float,
    q_trans: float,
    max_bridge_frames: int,
    frame_numbers: IntArray,
    robust: str,
    robust_k: float,
    marginals: bool,
) -> tuple[FloatArray, FloatArray, FloatArray, list[str], dict[str, Any]]:
    """Per-frame poses smoothed by a white-noise-acceleration prior (GTSAM ``WnoaMotionFactorPose3``).

    Nodes ``T_world_body`` and body twists; each measured frame adds a pose prior with its
    covariance; a gap of at most ``max_bridge_frames`` frames between measured frames is bridged
    (its frames' poses come from the prior alone). q_rot [rad^2/s^3], q_trans [m^2/s^3]: the PSDs."""
    import gtsam
    from gtsam.symbol_shorthand import V, X

    started = time.perf_counter()
    F = len(t_s)
    meas = np.flatnonzero(measured)
    # Frames in the graph: the measured ones and those in short gaps between them.
    in_graph = measured.copy()
    for a, b in itertools.pairwise(meas):
        if b - a > 1 and frame_numbers[b] - frame_numbers[a] - 1 <= max_bridge_frames:
            in_graph[a + 1 : b] = True
    nodes = np.flatnonzero(in_graph)
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    psd = np.array([q_rot] * 3 + [q_trans] * 3)
    n_motion = 0
    starts = _initial_poses(t_s, R, t, measured, nodes)
    for j, node in enumerate(nodes):
        k = int(node)
        Rk, tk = starts[k]
        values.insert(X(k), _pose(Rk, tk))
        values.insert(V(k), _initial_twist(starts, nodes, j, t_s))
        if measured[k]:
            Jinv = np.zeros((6, 6))
            Jinv[:3, :3] = Rk.T
            Jinv[3:, 3:] = Rk.T
            C_body = Jinv @ cov[k] @ Jinv.T
            C_body = 0.5 * (C_body + C_body.T)
            base = gtsam.noiseModel.Gaussian.Covariance(C_body)
            nm: Any = base
            if robust != "none":
                est = (
                    gtsam.noiseModel.mEstimator.Huber if robust == "huber" else gtsam.noiseModel.mEstimator.Cauchy
                ).Create(robust_k)
                nm = gtsam.noiseModel.Robust.Create(est, base)
            graph.add(gtsam.PriorFactorPose3(X(k), _pose(Rk, tk), nm))
        if (j > 0 and nodes[j - 1] == k - 1) or (j > 0 and in_graph[nodes[j - 1] : k + 1].all()):
            p = int(nodes[j - 1])
            s0 = gtsam.StateData(X(p), V(p), float(t_s[p]))
            s1 = gtsam.StateData(X(k), V(k), float(t_s[k]))
            graph.add(gtsam.WnoaMotionFactorPose3(s0, s1, psd))
            n_motion += 1
        elif j > 0:  # a new chain: a weak prior on its twist keeps it determined
            graph.add(gtsam.PriorFactorVector(V(k), np.zeros(6), gtsam.noiseModel.Isotropic.Sigma(6, 1e3)))
    if len(nodes):
        graph.add(gtsam.PriorFactorVector(V(int(nodes[0])), np.zeros(6), gtsam.noiseModel.Isotropic.Sigma(6, 1e3)))
    result, iterations, chi2 = _solve(graph, values)
    Rout, tout, cout = no_poses(F)
    marg = solve_marginals(graph, result) if marginals else None
    for node in nodes:
        k = int(node)
        T = result.atPose3(X(k))
        Rk = T.rotation().matrix()
        Rout[k], tout[k] = Rk, T.translation()
        if marg is not None:
            J = np.zeros((6, 6))
            J[:3, :3] = Rk
            J[3:, 3:] = Rk
            cout[k] = J @ marg.marginalCovariance(X(int(k))) @ J.T
    status = [STATUS_MEASURED if measured[k] else (STATUS_BRIDGED if in_graph[k] else STATUS_MISSING) for k in range(F)]
    info = {
        "nodes": len(nodes),
        "factors": {"pose": int(measured.sum()), "motion": n_motion},
        "iterations": iterations,
        "chi2_final": chi2,
        "solver": "gtsam LM",
        "psd": {"angular_rad2_s3": q_rot, "linear_m2_s3": q_trans},
        "time_s": time.perf_counter() - started,
    }
    return Rout, tout, cout, status, info


def _initial_poses(
    t_s: FloatArray, R: FloatArray, t: FloatArray, measured: BoolArray, nodes: IntArray
) -> dict[int, tuple[FloatArray, FloatArray]]:
    """Each node's starting pose: its fit, or between two fits, the interpolation of their poses."""
    from .geometry import exp_so3, log_so3

    meas = np.flatnonzero(measured)
    out: dict[int, tuple[FloatArray, FloatArray]] = {}
    for node in nodes:
        k = int(node)
        if measured[k]:
            out[k] = (R[k], t[k])
            continue
        a, b = meas[meas < k][-1], meas[meas > k][0]
        w = (t_s[k] - t_s[a]) / (t_s[b] - t_s[a])
        out[k] = (exp_so3(w * log_so3(R[b] @ R[a].T)) @ R[a], (1 - w) * t[a] + w * t[b])
    return out


def _initial_twist(
    starts: dict[int, tuple[FloatArray, FloatArray]], nodes: IntArray, j: int, t_s: FloatArray
) -> FloatArray:
    """A node's starting body twist, from its pose and its neighbour's (LM starts near the answer)."""
    import gtsam

    a, b = (int(nodes[j]), int(nodes[j + 1])) if j + 1 < len(nodes) else (int(nodes[j - 1]), int(nodes[j]))
    if a == b or t_s[b] <= t_s[a]:
        return np.zeros(6)
    rel = _pose(*starts[a]).between(_pose(*starts[b]))
    return np.asarray(gtsam.Pose3.Logmap(rel)) / (t_s[b] - t_s[a])


def typical_sigma(cov: FloatArray, start: int) -> float:
    """Typical per-axis 1-sigma of the rotation (start 0) or position (start 3) block."""
    ok = ~np.isnan(cov[:, 0, 0])
    block = cov[ok, start : start + 3, start : start + 3]
    return float(np.sqrt(np.median(np.trace(block, axis1=1, axis2=2) / 3.0))) if ok.any() else 0.01


def auto_psd(
    t_s: FloatArray,
    R: FloatArray,
    t: FloatArray,
    measured: BoolArray,
    sigma_rot: float,
    sigma_pos: float,
    window_s: float = WINDOW_S,
) -> tuple[float, float]:
    """White-noise-acceleration PSDs (rotation [rad^2/s^3], translation [m^2/s^3]) from the measured
    poses: a white acceleration of PSD q changes the velocity by ``var = q T`` per axis over ``T``.
    Velocities are differenced over windows of ``window_s``, less what the pose noise alone gives
    (``6 sigma^2 / T^2`` per axis). sigma_rot [rad], sigma_pos [m]: per-axis pose noise."""
    from .geometry import log_so3

    k = np.flatnonzero(measured)
    if len(k) < 8:
        return 1.0, 0.1
    dt = float(np.median(np.diff(t_s[k])))
    w = max(1, min(round(window_s / max(dt, 1e-9)), len(k) // 3))
    a, b, c = k[: -2 * w], k[w:-w], k[2 * w :]
    T1, T2 = t_s[b] - t_s[a], t_s[c] - t_s[b]
    v1 = (t[b] - t[a]) / T1[:, None]
    v2 = (t[c] - t[b]) / T2[:, None]
    w1 = log_so3(R[b] @ np.transpose(R[a], (0, 2, 1))) / T1[:, None]
    w2 = log_so3(R[c] @ np.transpose(R[b], (0, 2, 1))) / T2[:, None]
    span = float(np.median(T1))
    per_axis_v = float(np.mean((v2 - v1) ** 2)) - 6.0 * sigma_pos**2 / span**2
    per_axis_w = float(np.mean((w2 - w1) ** 2)) - 6.0 * sigma_rot**2 / span**2
    floor_v = 0.1 * 6.0 * sigma_pos**2 / span**2
    floor_w = 0.1 * 6.0 * sigma_rot**2 / span**2
    return max(per_axis_w, floor_w) / span, max(per_axis_v, floor_v) / span
