"""Scoring a result against a simulation's truth (digest §8.4).

Per frame: reports whose two detections belong to one observable target are matched by
association; the rest are matched to the remaining observable targets by a Hungarian
assignment on the bound's Mahalanobis distance (d² ≤ 100; wrong associations); reports left
over are false targets unless their pair is a ghost pair; observable targets left over are
missed. The error ratio ``√(eᵀ C⁻¹ e / 3)`` (C the bound) and the NEES ``eᵀ Σ⁻¹ e / 3`` (Σ the
reported covariance) are computed on clean targets matched by association.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._typing import FloatArray


@dataclass
class Score:
    clean: int = 0
    clean_associated: int = 0
    clean_wrong: int = 0
    clean_missed: int = 0
    observable: int = 0
    missed: int = 0
    ambiguous: int = 0
    ambiguous_right: int = 0
    false_targets: int = 0
    excused_ghosts: int = 0
    ratio: list[float] = field(default_factory=list)
    nees: list[float] = field(default_factory=list)
    bound_m: list[float] = field(default_factory=list)
    error_m: list[float] = field(default_factory=list)

    def add(self, other: Score) -> None:
        for name, value in vars(other).items():
            mine = getattr(self, name)
            if isinstance(value, list):
                mine.extend(value)
            else:
                setattr(self, name, mine + value)

    @property
    def association(self) -> float:
        return self.clean_associated / self.clean if self.clean else float("nan")

    @property
    def missed_share(self) -> float:
        return self.clean_missed / self.clean if self.clean else float("nan")

    @property
    def false_share(self) -> float:
        return self.false_targets / self.observable if self.observable else float("nan")

    @property
    def ratio_rms(self) -> float:
        return float(np.sqrt(np.mean(np.square(self.ratio)))) if self.ratio else float("nan")

    @property
    def ratio_p99(self) -> float:
        return float(np.percentile(self.ratio, 99)) if self.ratio else float("nan")

    @property
    def nees_mean(self) -> float:
        return float(np.mean(self.nees)) if self.nees else float("nan")

    @property
    def max_error_m(self) -> float:
        return float(np.max(self.error_m)) if self.error_m else float("nan")


def score(result: dict[str, Any], truth: dict[str, Any]) -> Score:
    """Score a succeeded result document against the truth of the same simulation."""
    from scipy.optimize import linear_sum_assignment

    total = Score()
    for fr, tf in zip(result["frames"], truth["frames"], strict=True):
        s = Score()
        targets = tf["targets"]
        owner: dict[str, int] = {}
        for j, t in enumerate(targets):
            if t["observable"]:
                for did in t["detections"].values():
                    owner[did] = j
        ghosts = {tuple(g) for g in tf["ghost_pairs"]}
        matched: set[int] = set()
        leftover = []
        for rep in fr["targets"]:
            ids = list(rep["detections"].values())
            j1, j2 = owner.get(ids[0]), owner.get(ids[1])
            if j1 is not None and j1 == j2 and j1 not in matched:
                matched.add(j1)
                t = targets[j1]
                if t["clean"]:
                    s.clean_associated += 1
                    _errors(s, rep, t)
                elif t["ambiguous"]:
                    s.ambiguous_right += 1
            else:
                leftover.append(rep)
        rest = [j for j, t in enumerate(targets) if t["observable"] and j not in matched]
        position_matched: set[int] = set()
        if leftover and rest:
            d2 = np.array([[_mahalanobis2(rep, targets[j]) for j in rest] for rep in leftover])
            ri, ci = linear_sum_assignment(np.minimum(d2, 1e6))
            ok = d2[ri, ci] <= 100.0
            position_matched = {rest[c] for c in ci[ok]}
            taken = set(ri[ok].tolist())
            leftover = [rep for n, rep in enumerate(leftover) if n not in taken]
        for rep in leftover:
            if tuple(rep["detections"].values()) in ghosts:
                s.excused_ghosts += 1
            else:
                s.false_targets += 1
        for j, t in enumerate(targets):
            if not t["observable"]:
                continue
            s.observable += 1
            s.ambiguous += int(t["ambiguous"])
            if t["clean"]:
                s.clean += 1
                if j in position_matched:
                    s.clean_wrong += 1
                elif j not in matched:
                    s.clean_missed += 1
            if j not in matched and j not in position_matched:
                s.missed += 1
        total.add(s)
    return total


def _mahalanobis2(rep: dict[str, Any], t: dict[str, Any]) -> float:
    e = np.asarray(rep["position_m"]) - np.asarray(t["position_m"])
    return float(e @ np.linalg.solve(np.asarray(t["crlb_m2"]), e))


def _errors(s: Score, rep: dict[str, Any], t: dict[str, Any]) -> None:
    e: FloatArray = np.asarray(rep["position_m"]) - np.asarray(t["position_m"])
    s.ratio.append(float(np.sqrt(e @ np.linalg.solve(np.asarray(t["crlb_m2"]), e) / 3.0)))
    s.nees.append(float(e @ np.linalg.solve(np.asarray(rep["cov_m2"]), e) / 3.0))
    s.bound_m.append(float(t["sigma_bound_m"]))
    s.error_m.append(float(np.linalg.norm(e)))


def score_tracks(result: dict[str, Any], truth: dict[str, Any], *, min_frames: int) -> tuple[list[float], list[float]]:
    """Track fits against the truth at ``t_ref``: ratios to the single-frame bound there and
    NEES/3 of the fit's covariance, for tracks of one true target over ``min_frames`` frames."""
    owner: dict[str, set[int]] = {}
    for fr, tf in zip(result["frames"], truth["frames"], strict=True):
        by_id = {}
        for t in tf["targets"]:
            for did in t["detections"].values():
                if did is not None:
                    by_id[did] = t["target"]
        for t in fr["targets"]:
            targets = {by_id.get(d, -1) for d in t["detections"].values()}
            owner.setdefault(t["track"], set()).update(targets)
    truth_at = {f["t"]: f for f in truth["frames"]}
    ratios, nees = [], []
    for tr in result.get("tracks", []):
        members = owner.get(tr["id"], set())
        if len(members) != 1 or -1 in members or len(tr["frames"]) < min_frames:
            continue
        true = truth_at[tr["t_ref"]]["targets"][next(iter(members))]
        e = np.subtract(tr["position_m"], true["position_m"])
        ratios.append(float(np.sqrt(e @ np.linalg.solve(np.asarray(true["crlb_m2"]), e) / 3.0)))
        nees.append(float(e @ np.linalg.solve(np.asarray(tr["cov_m2"]), e) / 3.0))
    return ratios, nees
