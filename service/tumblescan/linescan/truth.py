"""Ground truth of a simulation as JSON, and its comparison with an estimate."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..errors import MalformedInputError
from ..io.json_text import parse_json
from ..target.motion import Motion
from .result import MotionResult


def motion_to_json(motion: Motion) -> dict[str, Any]:
    m = motion.canonical()
    return {
        "reference_time_s": m.reference_time_s,
        "spin_axis": list(m.spin_axis),
        "spin_rate_deg_s": float(np.degrees(m.spin_rate_rad_s)),
        "precession_axis": list(m.precession_axis),
        "precession_rate_deg_s": float(np.degrees(m.precession_rate_rad_s)),
        "center_m": list(m.center_m),
    }


def motion_from_json(obj: dict[str, Any]) -> Motion:
    return Motion.from_degrees(
        spin_axis=obj["spin_axis"],
        spin_rate_deg_s=obj["spin_rate_deg_s"],
        precession_axis=obj["precession_axis"],
        precession_rate_deg_s=obj["precession_rate_deg_s"],
        center_m=obj["center_m"],
        reference_time_s=obj["reference_time_s"],
    )


def angle_deg(a: Any, b: Any) -> float:
    """Angle between two vectors, accurate near 0 (atan2 of cross and dot)."""
    u, v = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.degrees(np.arctan2(np.linalg.norm(np.cross(u, v)), u @ v)))


def errors_against(result: MotionResult, truth: Motion) -> dict[str, float]:
    """Estimate minus truth at the estimate's reference time: axis angles in degrees,
    rates in deg/s, centre distance in metres (spin-only: distance of the truth's centre
    from the estimated spin axis)."""
    T = result.reference_time_s
    spin_axis_true = truth.spin_axis_at(T)
    out = {
        "spin_axis_deg": angle_deg(result.spin.axis, spin_axis_true),
        "spin_rate_deg_s": result.spin.rate_deg_s - float(np.degrees(truth.spin_rate_rad_s)),
    }
    c_est = np.asarray(result.precession.center_m)
    c_true = np.asarray(truth.center_m)
    if result.precession.axis is not None:
        out["precession_axis_deg"] = angle_deg(result.precession.axis, truth.precession_axis)
        out["precession_rate_deg_s"] = result.precession.rate_deg_s - float(np.degrees(truth.precession_rate_rad_s))
        out["center_m"] = float(np.linalg.norm(c_est - c_true))
    else:
        d = c_true - c_est
        axis = np.asarray(result.spin.axis)
        out["center_m"] = float(np.linalg.norm(d - axis * (axis @ d)))
    return out


def load_truth(path: Path) -> Motion:
    """The ``motion`` of a ``truth.json`` written by ``tumblescan simulate``; a file that is not
    one is refused naming what is wrong (not JSON, no ``motion``, or which of its fields)."""
    doc = parse_json(path.read_bytes(), "truth", error=MalformedInputError)
    motion = doc.get("motion") if isinstance(doc, dict) else None
    if not isinstance(motion, dict):
        raise MalformedInputError(
            "'truth' has no 'motion' object (a truth.json from simulate)", field="truth"
        ) from None
    for key, size in MOTION_FIELDS.items():
        value = motion.get(key)
        ok = (
            _is_finite_number(value)
            if size == 0
            else (isinstance(value, list) and len(value) == size and all(_is_finite_number(v) for v in value))
        )
        if not ok:
            what = "a finite number" if size == 0 else f"a list of {size} finite numbers"
            raise MalformedInputError(f"'truth': motion.{key} must be {what}", field=f"truth.motion.{key}")
        if key.endswith("_axis") and not np.linalg.norm(np.asarray(value, dtype=float)) > 0:
            raise MalformedInputError(f"'truth': motion.{key} is the zero vector: an axis needs a direction",
                                      field=f"truth.motion.{key}")  # fmt: skip
    try:
        return motion_from_json(motion)
    except ValueError as exc:  # e.g. a zero-length axis
        raise MalformedInputError(f"'truth': the motion is not valid: {exc}", field="truth.motion") from None


# Each field of a truth file's motion: 0 for a number, else the length of its vector.
MOTION_FIELDS = {
    "spin_axis": 3,
    "spin_rate_deg_s": 0,
    "precession_axis": 3,
    "precession_rate_deg_s": 0,
    "center_m": 3,
    "reference_time_s": 0,
}


def _is_finite_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and bool(np.isfinite(v))
