"""Simulated bearings jobs with truth (digest §8): noisy and noise-free input documents, the
association and the single-frame bound per target, ghosts and ambiguity, and invalid copies.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from .._typing import FloatArray
from .associate import gated_candidates, observations
from .epipolar import baseline_basis
from .geometry import Observation, bearings_of, crlb, triangulate, wrap_rad
from .inputs import INPUT_SCHEMA, UNITS, parse_input
from .scenes import DEFAULT_TARGETS, SceneGeometry, build_scene

GHOST_CHI2 = 25.0
AMBIGUITY_MARGIN = 4.0


class SimulationConfig(BaseModel):
    """What to simulate."""

    model_config = ConfigDict(extra="forbid")
    scene: str = "paper"
    seed: int = 0
    targets: int | None = Field(default=None, ge=1, le=5000)
    frames: int = Field(default=10, ge=1, le=1000)
    clutter: float = Field(default=0.0, ge=0.0, le=10.0, description="false alarms per station and frame, per target")
    p_miss: float = Field(default=0.0, ge=0.0, lt=1.0)


@dataclass
class Simulation:
    """The input documents (noisy and noise-free: same ids, same order) and the truth."""

    input: dict[str, Any]
    input_noise_free: dict[str, Any]
    truth: dict[str, Any]
    geometry: SceneGeometry = field(repr=False)


def simulate(config: SimulationConfig) -> Simulation:
    """Draw a scene, measure it at both stations and compute the truth."""
    rng = np.random.default_rng(config.seed)
    k = config.targets or DEFAULT_TARGETS[config.scene]
    geo = build_scene(config.scene, rng, k, config.frames)
    brightness = rng.uniform(10.0, 30.0, size=k)
    r_ref = float(np.median(np.linalg.norm(geo.p_job_m[0] - geo.stations[0].p_job_m, axis=1)))
    frames, frames_clean, truth_frames = [], [], []
    for f, t in enumerate(geo.t_s):
        det, det_clean, ids = {}, {}, {}
        for s, st in enumerate(geo.stations):
            noisy, clean, ids[s] = _measure_station(rng, geo, f, s, config, brightness, r_ref)
            det[st.id], det_clean[st.id] = noisy, clean
        index = f
        frames.append({"index": index, "t": float(t), "detections": det})
        frames_clean.append({"index": index, "t": float(t), "detections": det_clean})
        truth_frames.append({"index": index, "t": float(t), "ids": ids})
    doc = _document(geo, frames)
    doc_clean = _document(geo, frames_clean)
    truth = _truth(config, geo, doc, truth_frames, k)
    return Simulation(input=doc, input_noise_free=doc_clean, truth=truth, geometry=geo)


def _measure_station(
    rng: np.random.Generator,
    geo: SceneGeometry,
    f: int,
    s: int,
    config: SimulationConfig,
    brightness: FloatArray,
    r_ref: float,
) -> tuple[list[dict[str, Any]], list[dict[str, Any]], list[str | None]]:
    """One station's detections in one frame: true bearings plus noise, misses, false alarms,
    sorted by azimuth and numbered after sorting. Returns noisy, noise-free and the id of each
    target's detection (None when missed)."""
    st = geo.stations[s]
    p = geo.p_job_m[f]
    k = p.shape[0]
    az, el = bearings_of(p, st)
    sig = np.radians(geo.sigma_deg)
    sig_az = sig / np.cos(el) if geo.focal_plane else np.full(k, sig)
    az_n = az + rng.normal(size=k) * sig_az
    el_n = el + rng.normal(size=k) * sig
    over = np.abs(el_n) > np.pi / 2  # reflect over the zenith (or nadir)
    el_n[over] = np.sign(el_n[over]) * np.pi - el_n[over]
    az_n[over] += np.pi
    rng_m = np.linalg.norm(p - st.p_job_m, axis=1)
    snr = brightness * (r_ref / rng_m) ** 2 * rng.lognormal(0.0, 0.2, size=k)
    seen = rng.uniform(size=k) >= config.p_miss
    n_fa = int(rng.poisson(config.clutter * k)) if config.clutter > 0 else 0
    centre = float(np.angle(np.mean(np.exp(1j * az))))
    rel = wrap_rad(az - centre)
    lo_az, hi_az = rel.min() - np.radians(0.5), rel.max() + np.radians(0.5)
    lo_el, hi_el = el.min() - np.radians(0.5), min(el.max() + np.radians(0.5), np.radians(89.0))
    fa_az = centre + rng.uniform(lo_az, hi_az, size=n_fa)
    fa_el = rng.uniform(lo_el, hi_el, size=n_fa)
    fa_snr = rng.uniform(3.0, 6.0, size=n_fa)
    # Rows: (az noisy, el noisy, az true, el true, snr, target or -1).
    rows = [(az_n[j], el_n[j], az[j], el[j], snr[j], j) for j in np.flatnonzero(seen).tolist()]
    rows += [(fa_az[j], fa_el[j], fa_az[j], fa_el[j], fa_snr[j], -1) for j in range(n_fa)]
    rows.sort(key=lambda r: float(wrap_rad(r[0])))
    noisy, clean = [], []
    ids: list[str | None] = [None] * k
    for n, (an, en, at, et, sn, tgt) in enumerate(rows):
        did = f"{st.id}.{f}.{n}"
        a = {"id": did, "az_deg": float(np.degrees(wrap_rad(an))), "el_deg": float(np.degrees(en)), "snr": float(sn)}
        b = {"id": did, "az_deg": float(np.degrees(wrap_rad(at))), "el_deg": float(np.degrees(et)), "snr": float(sn)}
        if geo.focal_plane:
            a["sigma_az_deg"] = float(geo.sigma_deg / np.cos(en))
            b["sigma_az_deg"] = float(geo.sigma_deg / np.cos(et))
        noisy.append(a)
        clean.append(b)
        if tgt >= 0:
            ids[tgt] = did
    return noisy, clean, ids


def _document(geo: SceneGeometry, frames: list[dict[str, Any]]) -> dict[str, Any]:
    stations = []
    for st in geo.stations:
        entry: dict[str, Any] = {
            "id": st.id,
            "sigma_az_deg": geo.sigma_deg,
            "sigma_el_deg": geo.sigma_deg,
        }
        if geo.frame == "ecef":
            assert st.geodetic is not None
            lat, lon, h = st.geodetic
            entry["geodetic"] = {"lat_deg": lat, "lon_deg": lon, "height_m": h}
        else:
            entry["position_m"] = [float(x) for x in st.p_job_m]
        stations.append(entry)
    return {"schema": INPUT_SCHEMA, "frame": geo.frame, "units": dict(UNITS), "stations": stations, "frames": frames}


def _truth(
    config: SimulationConfig, geo: SceneGeometry, doc: dict[str, Any], truth_frames: list[dict[str, Any]], k: int
) -> dict[str, Any]:
    """Per frame and target: position, detection ids, observability, the bound, ambiguity;
    per frame the ghost pairs (non-true pairs with ML χ² ≤ 25)."""
    parsed = parse_input(doc)
    basis = baseline_basis(parsed.stations)
    out_frames = []
    for f, (fr, tf) in enumerate(zip(parsed.frames, truth_frames, strict=True)):
        dets = fr.detections
        pos = {d: {i: n for n, i in enumerate(dd.ids)} for d, dd in enumerate(dets)}
        ids1, ids2 = tf["ids"][0], tf["ids"][1]
        observable = np.array([a is not None and b is not None for a, b in zip(ids1, ids2, strict=True)])
        bound = _bound(geo, f, dets, pos, ids1, ids2)
        amb, ghosts, chi2_true = _ambiguity(parsed.stations, basis, dets, pos, ids1, ids2, observable)
        targets = []
        for j in range(k):
            targets.append(
                {
                    "target": j,
                    "position_m": [float(x) for x in geo.p_job_m[f, j]],
                    "detections": {parsed.stations[0].id: ids1[j], parsed.stations[1].id: ids2[j]},
                    "observable": bool(observable[j]),
                    "ambiguous": bool(amb[j]),
                    "clean": bool(observable[j] and not amb[j]),
                    "chi2": None if not observable[j] else float(chi2_true[j]),
                    "crlb_m2": bound[j].tolist(),
                    "sigma_bound_m": float(np.sqrt(np.trace(bound[j]))),
                }
            )
        out_frames.append({"index": fr.index, "t": fr.t_s, "targets": targets, "ghost_pairs": ghosts})
    return {
        "schema": "tumblescan.bearings.truth/1",
        "config": config.model_dump(),
        "targets": k,
        "frame": geo.frame,
        "frames": out_frames,
    }


def _bound(
    geo: SceneGeometry,
    f: int,
    dets: Any,
    pos: dict[int, dict[str, int]],
    ids1: list[str | None],
    ids2: list[str | None],
) -> FloatArray:
    """The CRLB at the true positions, with each detection's declared σ (σ/cos el for a
    focal-plane sensor when the detection was missed)."""
    p = geo.p_job_m[f]
    obs = []
    for s, ids in enumerate((ids1, ids2)):
        _, el = bearings_of(p, geo.stations[s])
        sig = np.radians(geo.sigma_deg)
        sa = sig / np.cos(el) if geo.focal_plane else np.full(len(ids), sig)
        se = np.full(len(ids), sig)
        for j, did in enumerate(ids):
            if did is not None:
                n = pos[s][did]
                sa[j], se[j] = dets[s].sigma_az_rad[n], dets[s].sigma_el_rad[n]
        obs.append(Observation(np.zeros(len(ids)), el, sa, se))
    return crlb(p, geo.stations, (obs[0], obs[1]))


def _ambiguity(
    stations: Any,
    basis: Any,
    dets: Any,
    pos: dict[int, dict[str, int]],
    ids1: list[str | None],
    ids2: list[str | None],
    observable: np.ndarray,
) -> tuple[np.ndarray, list[list[str]], FloatArray]:
    """Ambiguous targets (a swap, or a partner swap with an unpaired detection, within +4 χ²),
    the ghost pairs and each observable target's own χ²."""
    k = len(ids1)
    obs_idx = np.flatnonzero(observable)
    a = np.array([pos[0][str(ids1[j])] for j in obs_idx], dtype=np.int64)
    b = np.array([pos[1][str(ids2[j])] for j in obs_idx], dtype=np.int64)
    chi2_true = np.full(k, np.nan)
    if obs_idx.size:
        chi2_true[obs_idx] = triangulate(stations, observations(dets, a, b)).chi2
    cand = gated_candidates(stations, basis, dets, GHOST_CHI2)
    chi2 = {(int(i), int(j)): float(c) for i, j, c in zip(cand.i1, cand.i2, cand.fix.chi2, strict=True)}
    owner1 = dict(zip(a.tolist(), obs_idx.tolist(), strict=True))
    owner2 = dict(zip(b.tolist(), obs_idx.tolist(), strict=True))
    amb = np.zeros(k, dtype=bool)
    ghosts = []
    for (i, j), c in chi2.items():
        t1, t2 = owner1.get(i), owner2.get(j)
        if t1 is not None and t1 == t2:
            continue
        ghosts.append([dets[0].ids[i], dets[1].ids[j]])
        if t1 is not None and t2 is not None:
            swap = chi2.get((int(a[obs_idx == t2][0]), int(b[obs_idx == t1][0])))
            if swap is not None and c + swap - chi2_true[t1] - chi2_true[t2] <= AMBIGUITY_MARGIN:
                amb[t1] = amb[t2] = True
        elif t1 is not None and c - chi2_true[t1] <= AMBIGUITY_MARGIN:
            amb[t1] = True
        elif t2 is not None and c - chi2_true[t2] <= AMBIGUITY_MARGIN:
            amb[t2] = True
    return amb, ghosts, chi2_true


def invalid_variants(doc: dict[str, Any]) -> list[tuple[str, str, str]]:
    """One invalid copy of ``doc`` per refusal rule of the contract: (name, JSON text, field
    the refusal must name)."""
    import copy
    import json

    fi = next(n for n, fr in enumerate(doc["frames"]) if all(fr["detections"].get(s["id"]) for s in doc["stations"]))
    s1, s2 = doc["stations"][0]["id"], doc["stations"][1]["id"]
    det0 = f"frames[{fi}].detections.{s1}[0]"
    out: list[tuple[str, str, str]] = []

    def variant(name: str, field: str, change: Any) -> None:
        d = copy.deepcopy(doc)
        change(d)
        out.append((name, json.dumps(d), field))

    def first(d: dict[str, Any]) -> dict[str, Any]:
        return dict(d["frames"][fi]["detections"][s1][0])

    def set_det(d: dict[str, Any], key: str, value: Any) -> None:
        d["frames"][fi]["detections"][s1][0][key] = value

    def to_ecef(d: dict[str, Any], lat: float = 34.0, lon: float = 108.0) -> None:
        d["frame"] = "ecef"
        for n, st in enumerate(d["stations"]):
            st.pop("position_m", None)
            st["geodetic"] = {"lat_deg": lat, "lon_deg": lon + 0.01 * n, "height_m": 100.0}

    variant("schema", "schema", lambda d: d.update(schema="tumblescan.bearings.input/2"))
    variant("frame", "frame", lambda d: d.update(frame="j2000"))
    variant("units_angle", "units", lambda d: d.update(units={"angle": "rad", "length": "m", "time": "s"}))
    variant("units_length", "units", lambda d: d.update(units={"angle": "deg", "length": "km", "time": "s"}))
    variant("three_stations", "stations", lambda d: d["stations"].append(dict(d["stations"][0], id="S3")))
    variant("one_station", "stations", lambda d: d["stations"].pop())
    variant("duplicate_station", "stations[1].id", lambda d: d["stations"][1].update(id=s1))
    variant(
        "coincident_stations",
        "stations",
        lambda d: (
            d["stations"][1].update({"position_m": [x + 0.3 for x in d["stations"][0]["position_m"]]})
            if doc["frame"] == "local_enu"
            else d["stations"][1].update(geodetic=dict(d["stations"][0]["geodetic"]))
        ),
    )
    if doc["frame"] == "local_enu":
        variant("missing_position", "stations[1].position_m", lambda d: d["stations"][1].pop("position_m"))
        far = [-1e308, 0.0, 0.0]
        variant("position_far", "stations[1].position_m", lambda d: d["stations"][1].update(position_m=far))
        variant("missing_geodetic", "stations[0].geodetic", lambda d: d.update(frame="ecef"))
        variant("lat_range", "stations[0].geodetic.lat_deg", lambda d: to_ecef(d, lat=95.0))
        variant("lon_range", "stations[0].geodetic.lon_deg", lambda d: to_ecef(d, lon=400.0))
    else:
        variant("missing_geodetic", "stations[1].geodetic", lambda d: d["stations"][1].pop("geodetic"))
        variant("missing_position", "stations[0].position_m", lambda d: d.update(frame="local_enu"))
        variant("lat_range", "stations[0].geodetic.lat_deg", lambda d: d["stations"][0]["geodetic"].update(lat_deg=-91))
        variant(
            "lon_range", "stations[1].geodetic.lon_deg", lambda d: d["stations"][1]["geodetic"].update(lon_deg=-181)
        )
    variant("sigma_missing", "stations[0].sigma_az_deg", lambda d: d["stations"][0].pop("sigma_az_deg"))
    variant("sigma_zero", "stations[0].sigma_el_deg", lambda d: d["stations"][0].update(sigma_el_deg=0.0))
    variant("sigma_tiny", "stations[0].sigma_az_deg", lambda d: d["stations"][0].update(sigma_az_deg=1e-300))
    huge = {"position_sigma_m": 1e300}
    variant("position_sigma_huge", "stations[1].position_sigma_m", lambda d: d["stations"][1].update(huge))
    variant("sigma_large", "stations[1].sigma_az_deg", lambda d: d["stations"][1].update(sigma_az_deg=5.0))
    variant("sigma_text", "stations[1].sigma_el_deg", lambda d: d["stations"][1].update(sigma_el_deg="0.02"))
    variant("det_sigma_negative", f"{det0}.sigma_az_deg", lambda d: set_det(d, "sigma_az_deg", -0.01))
    variant("el_above_90", f"{det0}.el_deg", lambda d: set_det(d, "el_deg", 95.0))
    variant("el_below_-90", f"{det0}.el_deg", lambda d: set_det(d, "el_deg", -90.5))
    variant("az_text", f"{det0}.az_deg", lambda d: set_det(d, "az_deg", "12.5"))
    variant("az_null", f"{det0}.az_deg", lambda d: set_det(d, "az_deg", None))
    variant("snr_zero", f"{det0}.snr", lambda d: set_det(d, "snr", 0))
    variant("el_missing", f"{det0}.el_deg", lambda d: d["frames"][fi]["detections"][s1][0].pop("el_deg"))
    variant(
        "duplicate_detection",
        f"frames[{fi}].detections.{s2}[0].id",
        lambda d: d["frames"][fi]["detections"][s2][0].update(id=first(d)["id"]),
    )
    variant(
        "unknown_station",
        f"frames[{fi}].detections.S9",
        lambda d: d["frames"][fi]["detections"].update(S9=[]),
    )
    if len(doc["frames"]) > 1:
        variant("t_not_increasing", "frames[1].t", lambda d: d["frames"][1].update(t=d["frames"][0]["t"]))
        variant("duplicate_index", "frames[1].index", lambda d: d["frames"][1].update(index=d["frames"][0]["index"]))
        variant("t_too_close", "frames[1].t", lambda d: d["frames"][1].update(t=d["frames"][0]["t"] + 1e-9))
    variant("t_far_from_epoch", "frames[0].t", lambda d: d["frames"][0].update(t=-1e308))
    variant("t_missing", "frames[0].t", lambda d: d["frames"][0].pop("t"))
    variant("no_frames", "frames", lambda d: d.update(frames=[]))
    # Non-finite numbers as JSON tokens, which only a text document can carry.
    for name, token, key in (
        ("az_nan", "NaN", "az_deg"),
        ("el_inf", "-Infinity", "el_deg"),
        ("t_inf", "Infinity", "t"),
    ):
        d = copy.deepcopy(doc)
        target = d["frames"][0] if key == "t" else d["frames"][fi]["detections"][s1][0]
        target[key] = "__TOKEN__"
        field = "frames[0].t" if key == "t" else f"{det0}.{key}"
        out.append((name, json.dumps(d).replace('"__TOKEN__"', token), field))
    out.append(("not_json", json.dumps(doc)[:-7], "input"))
    out.append(("not_object", "[1, 2, 3]", "input"))
    return out
