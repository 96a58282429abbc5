"""CPU seconds and answers of spin-from-images ("ours") on cached benchmark sequences, one JSON
line per sequence: to compare two versions of the code on the same inputs.

    OMP_NUM_THREADS=1 PYTHONPATH=service:client python -m bench.spin_from_images.speed \
        --cases oblique_100_noisy los_100_noisy --out bench/out/speed_after.jsonl

With ``PYTHONPATH=<other checkout>/service:<other checkout>/client:.`` the same script times the
other checkout's code. The modules the pipeline imports lazily (scipy.signal, scipy.optimize) are
imported before the clock starts, so the first case is not charged for them. When the case has a
``truth.json`` the row also carries the true rate, the error and whether it is within the
benchmark's tolerance ``max(3 σ_CRB, 0.5 %, 0.01 deg/s)``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from tumblescan.spin_rate.options import EstimateOptions
from tumblescan.spin_rate.pipeline import load_input, run


def measure(d: Path) -> dict[str, object]:
    """Rate, σ (deg/s), axis (camera frame), and the CPU and wall seconds of one run."""
    c0, t0 = time.process_time(), time.perf_counter()
    spin = run(load_input(d / "meta.json"), EstimateOptions(method="ours")).spin
    row: dict[str, object] = {
        "case": d.name, "rate": spin.rate_deg_s, "sigma": spin.sigma_rate_deg_s, "axis": spin.axis_camera,
        "cpu_s": time.process_time() - c0, "wall_s": time.perf_counter() - t0,
    }  # fmt: skip
    truth_path = d / "truth.json"
    if truth_path.exists() and spin.rate_deg_s is not None:
        truth = json.loads(truth_path.read_text())
        rate, crb = float(truth["rate_deg_s"]), float(truth["sigma_rate_crb_deg_s"])
        err = abs(float(spin.rate_deg_s) - rate)
        row.update(truth_rate=rate, err=err, within=err <= max(3 * crb, 0.005 * rate, 0.01))
    return row


def main() -> None:
    import importlib

    import cv2

    for name in ("scipy.optimize", "scipy.signal"):  # imported lazily by the pipeline: not charged to a case
        importlib.import_module(name)

    cv2.setNumThreads(1)  # CPU seconds of one core's work, whatever else runs
    ap = argparse.ArgumentParser()
    ap.add_argument("--cache", type=Path, default=Path(__file__).resolve().parent.parent / "out" / "spin_cache_512")
    ap.add_argument("--cases", nargs="+", required=True)
    ap.add_argument("--out", type=Path, required=True, help="JSON lines, appended")
    args = ap.parse_args()
    with args.out.open("a") as fh:
        for case in args.cases:
            row = measure(args.cache / case)
            print(json.dumps(row), flush=True)
            fh.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
