"""Tracks that pass from one body edge to another without a jump (the axis near the image plane):
cut into their rigid pieces under the fitted motion (``association.split_piecewise_tracks``)."""

from __future__ import annotations

import numpy as np

from tumblescan.spin_rate.association import split_piecewise_tracks
from tumblescan.spin_rate.rigid import Observations, fit_rigid
from tumblescan.spin_rate.rotation import rot, unit_from_angles
from tumblescan.spin_rate.search import best_of_starts, best_of_starts_without_strays
from tumblescan.spin_rate.starts import plane_ladder_starts

F_PX = 1100.0
K = np.array([[F_PX, 0.0, 256.0], [0.0, F_PX, 256.0], [0.0, 0.0, 1.0]])
RANGE_M = 40.0
FRAMES = 12


def _edges() -> list[tuple[np.ndarray, np.ndarray]]:
    """The 12 edges of a 1.6 x 1.4 x 2 m box (body frame, m), its long side (z) the spin axis."""
    half = np.array([0.8, 0.7, 1.0])
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
    return [
        (corners[i], corners[j])
        for i in range(8)
        for j in range(i + 1, 8)
        if np.sum(np.abs(corners[i] - corners[j]) > 1e-9) == 1
    ]


def _spliced_tracks(seed: int, rate_deg_s: float = 20.0) -> tuple[Observations, Observations, dict[str, object]]:
    """Every box edge seen in every frame (0.1 px of noise) while the box spins about its long side
    set 1° off the image plane; then each pair of edges along the axis that are neighbours on the
    box is spliced: the first edge's track takes the second edge's observations from the middle
    frame on, as a tracker that passed from a silhouette edge to the next one does. Returns the
    clean tracks, the spliced ones (the spliced tracks first) and the truth."""
    rng = np.random.default_rng(seed)
    axis = unit_from_angles(np.radians(89.0), rng.uniform(0, np.pi))
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(z, axis)
    R0 = rot(axis, rng.uniform(0, 2 * np.pi))[0] @ rot(v / np.linalg.norm(v), np.arctan2(np.linalg.norm(v), axis[2]))[0]
    c = np.array([rng.uniform(-2, 2), rng.uniform(-2, 2), RANGE_M])
    w = np.radians(rate_deg_s)
    t = np.cumsum(np.r_[0.0, np.radians(15.0) / w * rng.uniform(0.97, 1.03, FRAMES - 1)])
    edges = _edges()
    obs: dict[int, list[tuple[int, np.ndarray]]] = {j: [] for j in range(len(edges))}
    for k, tk in enumerate(t):
        R = rot(axis, w * tk)[0] @ R0
        for j, (p, q) in enumerate(edges):
            uv = np.array([K @ (c + R @ p), K @ (c + R @ q)])
            uv = uv[:, :2] / uv[:, 2:]
            d = (uv[1] - uv[0]) / np.linalg.norm(uv[1] - uv[0])
            obs[j].append((k, uv + rng.normal(0, 0.1, (2, 1)) * np.array([-d[1], d[0]])))
    along = [j for j, (p, q) in enumerate(edges) if abs(p[2] - q[2]) > 1e-9]  # the 4 edges along z
    # Neighbours on the box share a face: one coordinate (x or y) in common.
    pairs = [(along[0], b) for b in along[1:] if np.sum(np.isclose(edges[along[0]][0][:2], edges[b][0][:2])) == 1]
    a, b = pairs[0]
    c_, d_ = (j for j in along if j not in (a, b))
    mid = FRAMES // 2
    spliced = []
    for x, y in ((a, b), (c_, d_)):  # both pairs of opposite faces' edges
        spliced.append([o for o in obs[x] if o[0] < mid] + [o for o in obs[y] if o[0] >= mid])
        spliced.append([o for o in obs[y] if o[0] < mid])  # y's track before the switch
    rest = [obs[j] for j in range(len(edges)) if j not in along]
    truth = {"rate": w, "axis": axis, "c0": c / c[2], "t": t, "mid": mid}
    return _build(list(obs.values()), t), _build(spliced + rest, t), truth


def _build(tracks: list[list[tuple[int, np.ndarray]]], t: np.ndarray) -> Observations:
    trk = np.concatenate([np.full(len(tr), j) for j, tr in enumerate(tracks)])
    tt = np.array([t[k] for tr in tracks for k, _ in tr])
    ends = np.array([e for tr in tracks for _, e in tr])
    return Observations.build(trk, tt, ends, K)


def test_a_track_that_passes_to_a_neighbouring_edge_is_cut_where_it_does_and_no_other() -> None:
    clean, spliced, truth = _spliced_tracks(3)
    t0 = float(np.asarray(truth["t"])[0])
    fit = fit_rigid(clean, float(truth["rate"]), np.asarray(truth["axis"]), np.asarray(truth["c0"]), t0)  # type: ignore[arg-type]
    assert split_piecewise_tracks(clean, fit, t0) is None  # rigid lines are not cut
    pieces = split_piecewise_tracks(spliced, fit, t0)
    assert pieces is not None
    assert pieces.n_tracks == spliced.n_tracks + 2
    # The spliced track (0) now ends at the switch; a new track holds the rest.
    t = np.asarray(truth["t"])
    mid = int(truth["mid"])  # type: ignore[call-overload]
    for j in (0, 2):  # the spliced tracks, in order, end at the switch
        assert np.allclose(np.sort(pieces.t_s[pieces.track == j]), t[:mid])
    assert sorted(np.bincount(pieces.track).tolist()) == [FRAMES - mid] * 6 + [FRAMES] * 8  # no other cut


def test_spliced_tracks_near_the_image_plane_do_not_pull_the_rate() -> None:
    # Each spliced track is two rigid lines; one line through both pulls the fit (it cannot follow
    # the switch at the true rate). The search cuts it and compares the starts again, and keeps
    # both pieces (dropped whole as stray tracks, their observations were lost).
    _, spliced, truth = _spliced_tracks(3)
    t0 = float(np.asarray(truth["t"])[0])
    c0 = np.asarray(truth["c0"])
    rate = float(truth["rate"])  # type: ignore[arg-type]
    w_lo, w_hi = np.radians(0.5), np.radians(60.0)
    ladder = plane_ladder_starts(spliced, w_lo, w_hi, c0, 0.08, t0)
    slow = [(np.radians(2.0), unit_from_angles(np.radians(25.0), np.radians(120.0)), c0)]
    plain = best_of_starts(spliced, slow, t0, w_lo, w_hi, c0, 0.08, ladder)
    kept, fit = best_of_starts_without_strays(spliced, slow, t0, w_lo, w_hi, c0, 0.08, ladder)
    assert abs(plain.omega_rad_s - rate) / rate > 0.02  # the spliced tracks pull a plain search off
    assert abs(fit.omega_rad_s - rate) / rate < 0.005, np.degrees(fit.omega_rad_s)
    assert len(kept.track) == len(spliced.track)


def test_the_cut_reports_its_gain() -> None:
    clean, spliced, truth = _spliced_tracks(3)
    t0 = float(np.asarray(truth["t"])[0])
    fit = fit_rigid(clean, float(truth["rate"]), np.asarray(truth["axis"]), np.asarray(truth["c0"]), t0)  # type: ignore[arg-type]
    gain: list[float] = []
    assert split_piecewise_tracks(clean, fit, t0, gain) is None
    assert gain == [0.0]
    assert split_piecewise_tracks(spliced, fit, t0, gain) is not None
    assert gain[0] > 25.0 * 0.1**2  # over SPLIT_DELTA_CHI2 at the least scale, per cut


def test_the_multi_start_is_run_again_after_a_cut_only_when_the_refit_finalists_ask_for_it(monkeypatch) -> None:  # type: ignore[no-untyped-def]
    # After a cut the previous finalists are refitted to the pieces first; the whole multi-start is
    # run again only when the winner's rate moves or the cut's gain is a large part of the cost.
    import tumblescan.spin_rate.search as search

    _, spliced, truth = _spliced_tracks(3)
    t0 = float(np.asarray(truth["t"])[0])
    c0 = np.asarray(truth["c0"])
    w_lo, w_hi = np.radians(0.5), np.radians(60.0)
    ladder = plane_ladder_starts(spliced, w_lo, w_hi, c0, 0.08, t0)
    start = [(float(truth["rate"]), np.asarray(truth["axis"]), c0)]  # type: ignore[arg-type]
    calls: list[int] = []
    real = search.best_of_starts

    def counted(*args, **kwargs):  # type: ignore[no-untyped-def]
        calls.append(len(args[0].track))
        return real(*args, **kwargs)

    monkeypatch.setattr(search, "best_of_starts", counted)
    monkeypatch.setattr(search, "SPLIT_RESEARCH_RATE_REL", np.inf)
    monkeypatch.setattr(search, "SPLIT_RESEARCH_GAIN_FRAC", np.inf)
    finalists: list = []
    _, never = search.best_of_starts_without_strays(spliced, start, t0, w_lo, w_hi, c0, 0.08, ladder, finalists)
    assert len(calls) == 1  # the cut was made, but the refit finalists were kept
    assert any(f is never for f in finalists)
    calls.clear()
    monkeypatch.setattr(search, "SPLIT_RESEARCH_GAIN_FRAC", -1.0)
    search.best_of_starts_without_strays(spliced, start, t0, w_lo, w_hi, c0, 0.08, ladder)
    assert len(calls) >= 2  # every cut: the whole multi-start again
