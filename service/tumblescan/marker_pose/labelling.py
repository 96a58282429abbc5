"""A frame's points against the layout, without tracks: the robust rigid fit (Kabsch on the largest
set of points within the gate, then the frame's chi-square test) and the search over labellings
that identifies a frame from scratch by its distance signature (triplets of points matched to
triplets of layout markers, each hypothesis verified on every point).

A frame fails the chi-square test when it exceeds the gate and no single marker explains it (a
planar layout cannot localize an out-of-plane error).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np

from .._typing import BoolArray, FloatArray, IntArray
from .geometry import kabsch

FRAME_ALPHA = 1e-3  # false-alarm rate of the frame's chi-square test
THREE_MARKER_ALPHA = 1e-2  # the same for a frame of 3 markers
MAX_TRIPLETS = 80
MAX_HYPOTHESES_PER_TRIPLET = 24


@dataclass
class Gates:
    """Residual gate [m] and the frame chi-square thresholds by degrees of freedom."""

    sigma_m: float
    outlier_sigma: float
    chi2_max: FloatArray  # indexed by dof

    @classmethod
    def make(cls, sigma_m: float, outlier_sigma: float, max_dof: int = 3 * 300) -> Gates:
        from scipy.stats import chi2, norm

        # A single marker is tested at the outlier gate; the frame as a whole at FRAME_ALPHA, since
        # an error a rigid fit absorbs (out of a planar layout's plane) shows only in the sum.
        alpha = min(FRAME_ALPHA, 2.0 * float(norm.sf(outlier_sigma)) * 1e3)
        dof = np.arange(max_dof + 1)
        thr = np.where(dof > 0, chi2.isf(alpha, np.maximum(dof, 1)), 0.0)
        # Three markers cannot point at their outlier: their frame is held to a stricter test.
        thr[3] = chi2.isf(THREE_MARKER_ALPHA, 3)
        return cls(sigma_m, outlier_sigma, np.asarray(thr))

    @property
    def gate_m(self) -> float:
        return self.outlier_sigma * self.sigma_m

    def chi2_ok(self, chi2: float, n: int) -> bool:
        dof = 3 * n - 6
        return dof <= 0 or chi2 <= self.chi2_max[min(dof, len(self.chi2_max) - 1)]


@dataclass
class Fit:
    """A frame's rigid fit: pose, which of the given points are inliers, chi-square."""

    R: FloatArray
    t: FloatArray
    inlier: BoolArray
    chi2: float
    ok: bool


def fit_robust(p_body_m: FloatArray, y_m: FloatArray, gates: Gates) -> Fit | None:
    """Kabsch on the largest set of points within the gate (all of them, or the best consensus of
    3-point fits), then the frame's chi-square test (one marker may be dropped if it alone explains
    a failure). None when fewer than 3 points agree."""
    n = len(y_m)
    if n < 3:
        return None
    R, t = kabsch(p_body_m, y_m)
    r = np.sqrt(np.sum((y_m - p_body_m @ R.T - t) ** 2, axis=1))
    keep = r <= gates.gate_m
    if not keep.all():
        if n >= 4:
            # The largest consensus of 3-point fits; of equal ones, the one its own fit explains best.
            best, best_cost = keep, np.inf
            for c in combinations(range(n), 3):
                Rc, tc = kabsch(p_body_m[list(c)], y_m[list(c)])
                k = np.linalg.norm(y_m - p_body_m @ Rc.T - tc, axis=1) <= gates.gate_m
                if k.sum() < max(best.sum(), 3):
                    continue
                Rk, tk = kabsch(p_body_m[k], y_m[k])
                cost = float(np.sum((y_m[k] - p_body_m[k] @ Rk.T - tk) ** 2))
                if k.sum() > best.sum() or cost < best_cost:
                    best, best_cost = k, cost
            keep = best
        for _ in range(n):
            if keep.sum() < 3:
                return None
            R, t = kabsch(p_body_m[keep], y_m[keep])
            r = np.linalg.norm(y_m - p_body_m @ R.T - t, axis=1)
            worst = int(np.argmax(np.where(keep, r, -1.0)))
            if r[worst] <= gates.gate_m:
                break
            keep[worst] = False
    chi2 = float(np.sum(r[keep] ** 2) / gates.sigma_m**2)
    if gates.chi2_ok(chi2, int(keep.sum())):
        return Fit(R, t, keep, chi2, True)
    return _one_out(p_body_m, y_m, keep, gates, R, t, chi2)


def _one_out(
    p: FloatArray, y: FloatArray, keep: BoolArray, gates: Gates, R: FloatArray, t: FloatArray, chi2: float
) -> Fit:
    passing = []
    idx = np.flatnonzero(keep)
    if len(idx) >= 4:
        for j in idx:
            k = keep.copy()
            k[j] = False
            Rj, tj = kabsch(p[k], y[k])
            c = float(np.sum(np.linalg.norm(y[k] - p[k] @ Rj.T - tj, axis=1) ** 2) / gates.sigma_m**2)
            if gates.chi2_ok(c, int(k.sum())):
                passing.append((j, Rj, tj, c))
    if len(passing) == 1:
        j, Rj, tj, c = passing[0]
        k = keep.copy()
        k[j] = False
        return Fit(Rj, tj, k, c, True)
    return Fit(R, t, keep, chi2, False)


def search(y_m: FloatArray, layout_m: FloatArray, gates: Gates) -> list[tuple[IntArray, Fit]]:
    """Identify a frame's points from scratch: the best hypotheses (marker index per point, -1 for
    none; the fit), all with the same largest number of inliers; one when the frame is unambiguous.

    Triplets of points whose three distances match three layout markers give pose hypotheses;
    each is scored by how many points land on a marker (then by chi-square)."""
    from scipy.optimize import linear_sum_assignment

    n, M = len(y_m), len(layout_m)
    if n < 3 or M < 3:
        return []
    tol = gates.gate_m * np.sqrt(2.0)
    dY = np.linalg.norm(y_m[:, None] - y_m[None], axis=-1)
    dL = np.linalg.norm(layout_m[:, None] - layout_m[None], axis=-1)
    compat = np.abs(dY[:, :, None, None] - dL[None, None]) < tol  # (n, n, M, M)
    triplets = sorted(combinations(range(n), 3), key=lambda c: -_area(y_m[list(c)]))[:MAX_TRIPLETS]
    found: dict[tuple[int, ...], tuple[int, float, IntArray, Fit]] = {}
    for i, j, k in triplets:
        cand = compat[i, j][:, :, None] & compat[j, k][None, :, :] & compat[i, k][:, None, :]
        for a, b, c in np.argwhere(cand)[:MAX_HYPOTHESES_PER_TRIPLET]:
            R, t = kabsch(layout_m[[a, b, c]], y_m[[i, j, k]])
            assign = _nearest(y_m, layout_m @ R.T + t, gates.gate_m, linear_sum_assignment)
            if np.sum(assign >= 0) < 3:
                continue
            used = assign >= 0
            fit = fit_robust(layout_m[assign[used]], y_m[used], gates)
            if fit is None or not fit.ok:
                continue
            assign[np.flatnonzero(used)[~fit.inlier]] = -1
            found[tuple(assign.tolist())] = (int(np.sum(assign >= 0)), fit.chi2, assign, fit)
            if n >= 4 and found[tuple(assign.tolist())][0] >= min(n, M):
                break
    if not found:
        return []
    top = max(h[0] for h in found.values())
    return [(h[2], h[3]) for h in sorted(found.values(), key=lambda h: h[1]) if h[0] == top]


def _area(p: FloatArray) -> float:
    return float(np.linalg.norm(np.cross(p[1] - p[0], p[2] - p[0])))


def _nearest(y_m: FloatArray, q_m: FloatArray, gate_m: float, lsa: object) -> IntArray:
    """Points to predicted markers, one to one, within the gate; a marker with two points within
    the gate (a glint next to a sphere) takes neither."""
    d = np.linalg.norm(y_m[:, None] - q_m[None], axis=-1)
    near = d < gate_m
    crowded = near.sum(axis=0) > 1
    cost = np.where(near & ~crowded[None], d, 1e6)
    rows, cols = lsa(cost)  # type: ignore[operator]
    assign = np.full(len(y_m), -1, dtype=np.int64)
    good = cost[rows, cols] < 1e6
    assign[rows[good]] = cols[good]
    return assign
