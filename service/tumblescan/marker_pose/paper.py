"""The paper's method, kept for benchmarks: vector-cross (VC) poses (eqs. 10-14) against a layout
measured once at the zero instant, chained frame to frame (eq. 15), then a pose graph of the
chain's relative poses with loop closures at each segment start (eq. 16), solved in GTSAM.

Gaps the paper leaves are filled as the digest says: ``D_w D_m^-1`` is projected onto SO(3) by
SVD and X is the midpoint of the diagonals' common perpendicular. Information matrices are not
given in the paper; isotropic ones from the point noise and the layout size are used.
"""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray
from .graph import STATUS_MEASURED, STATUS_MISSING, GraphResult, no_poses
from .identify import Association
from .markers_io import MarkerInput


def vc_pose(P_m: FloatArray, P_w: FloatArray) -> tuple[FloatArray, FloatArray]:
    """VC pose from 4 markers in order P1..P4 (body (4, 3) and world (4, 3)) -> (R_world_body, t)."""

    def frame(P: FloatArray) -> tuple[FloatArray, FloatArray]:
        a1 = (P[2] - P[0]) / np.linalg.norm(P[2] - P[0])
        a2 = (P[3] - P[1]) / np.linalg.norm(P[3] - P[1])
        b = np.cross(a1, a2)
        D = np.column_stack([a1, a2, b / np.linalg.norm(b)])
        # X: midpoint of the common perpendicular of lines P1P3 and P2P4.
        w0 = P[0] - P[1]
        A = np.array([[a1 @ a1, -a1 @ a2], [a1 @ a2, -a2 @ a2]])
        s, u = np.linalg.lstsq(A, -np.array([a1 @ w0, a2 @ w0]), rcond=None)[0]
        return D, 0.5 * (P[0] + s * a1 + P[1] + u * a2)

    D_m, X_m = frame(P_m)
    D_w, X_w = frame(P_w)
    U, _, Vt = np.linalg.svd(D_w @ np.linalg.inv(D_m))
    R = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt
    return R, X_w - R @ X_m


def paper_graph(
    data: MarkerInput, assoc: Association, layout_m: FloatArray, sigma: float, *, marginals: bool
) -> GraphResult:
    import gtsam
    from gtsam.symbol_shorthand import X

    F, M = data.n_frames, len(layout_m)
    # 1. Each frame's four lowest-numbered identified markers, in the world.
    pts: list[dict[int, FloatArray]] = [{} for _ in range(F)]
    for i in np.flatnonzero(assoc.obs_marker >= 0):
        pts[data.obs_frame[i]][int(assoc.obs_marker[i])] = data.xyz_m[i]
    # 2. The layout as measured at the zero instant (the first frame with 4 markers), frame 0 pose.
    first = next((f for f in range(F) if len(pts[f]) >= 4), None)
    R, t, cov = no_poses(F)
    if first is None:
        return GraphResult(R, t, cov, [STATUS_MISSING] * F, layout_m, np.zeros(M), _info(0, 0, 0, 0.0))
    # 3. Chain: within a frame pair sharing 4 markers, the relative VC pose; each segment start is
    #    also relocalized against the zero-instant markers (a loop closure).
    ref = {m: p for m, p in pts[first].items()}
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    size = float(np.max(np.linalg.norm(layout_m - layout_m.mean(axis=0), axis=1)))
    rel_noise = gtsam.noiseModel.Diagonal.Sigmas(np.r_[[np.sqrt(2) * sigma / size] * 3, [np.sqrt(2) * sigma] * 3])
    loop_noise = gtsam.noiseModel.Diagonal.Sigmas(np.r_[[2 * sigma / size] * 3, [2 * sigma] * 3])
    T_prev, f_prev = gtsam.Pose3(), first
    values.insert(X(first), T_prev)
    graph.add(gtsam.PriorFactorPose3(X(first), T_prev, gtsam.noiseModel.Isotropic.Sigma(6, 1e-6)))
    in_graph = [first]
    for f in range(first + 1, F):
        common = sorted(set(pts[f]) & set(pts[f_prev]))[:4]
        with_ref = sorted(set(pts[f]) & set(ref))[:4]
        if len(common) == 4:
            Ra, ta = vc_pose(np.array([pts[f_prev][m] for m in common]), np.array([pts[f][m] for m in common]))
            # Relative motion of the body between the frames, in the zero-instant body frame.
            rel = gtsam.Pose3(gtsam.Rot3(Ra), ta)
            T_f = rel.compose(T_prev)
            values.insert(X(f), T_f)
            graph.add(gtsam.BetweenFactorPose3(X(f_prev), X(f), T_prev.between(T_f), rel_noise))
        elif len(with_ref) == 4:  # a new segment: relocalize against the zero-instant markers
            Rr, tr = vc_pose(np.array([ref[m] for m in with_ref]), np.array([pts[f][m] for m in with_ref]))
            T_f = gtsam.Pose3(gtsam.Rot3(Rr), tr)
            values.insert(X(f), T_f)
            graph.add(gtsam.BetweenFactorPose3(X(first), X(f), T_f, loop_noise))
        else:
            continue
        T_prev, f_prev = T_f, f
        in_graph.append(f)
    params = gtsam.LevenbergMarquardtParams()
    opt = gtsam.LevenbergMarquardtOptimizer(graph, values, params)
    result = opt.optimize()
    marg = gtsam.Marginals(graph, result) if marginals else None
    # 4. Poses in the layout's body frame: world <- zero-instant world motion <- layout fit at zero.
    from .geometry import kabsch

    common0 = sorted(ref)
    R0, t0 = kabsch(layout_m[common0], np.array([ref[m] for m in common0]))
    T0 = gtsam.Pose3(gtsam.Rot3(R0), t0)
    for f in in_graph:
        T = result.atPose3(X(f)).compose(T0)
        R[f], t[f] = T.rotation().matrix(), T.translation()
        if marg is not None:
            C = marg.marginalCovariance(X(f))
            J = np.zeros((6, 6))
            J[:3, :3] = R[f]
            J[3:, 3:] = R[f]
            cov[f] = J @ C @ J.T
    status = [STATUS_MEASURED if not np.isnan(R[f, 0, 0]) else STATUS_MISSING for f in range(F)]
    return GraphResult(
        R,
        t,
        cov,
        status,
        layout_m,
        np.zeros(M),
        _info(len(in_graph), M, graph.size(), 2 * graph.error(result), opt.iterations()),
    )


def _info(nodes: int, M: int, factors: int, chi2: float, iterations: int = 0) -> dict[str, object]:
    return {
        "nodes": nodes,
        "landmarks": M,
        "factors": {"between": factors},
        "iterations": iterations,
        "chi2_final": chi2,
        "dof": max(6 * factors - 6 * nodes, 0),
        "solver": "gtsam LM (paper: VC chain + pose graph)",
        "time_s": 0.0,
    }
