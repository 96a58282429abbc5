"""CPU seconds and answers of spin-from-images ("ours") on cached benchmark sequences, one JSON
line per sequence: to compare two versions of the code on the same inputs.

    OMP_NUM_THREADS=1 PYTHONPATH=service:client python -m bench.spin_from_images.speed \
        --cases oblique_100_noisy los_100_noisy --out bench/out/speed_after.jsonl
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
    return {"case": d.name, "rate": spin.rate_deg_s, "sigma": spin.sigma_rate_deg_s, "axis": spin.axis_camera,
            "cpu_s": time.process_time() - c0, "wall_s": time.perf_counter() - t0}  # fmt: skip


def main() -> None:
    import cv2

    cv2.setNumThreads(1)  # CPU seconds of one core's work, whatever else runs
    ap = argparse.ArgumentParser()
    ap.add_argument("--cache", type=Path, default=Path(__file__).resolve().parent.parent / "out" / "spin_cache_512")
    ap.add_argument("--cases", nargs="+", required=True)
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    with args.out.open("w") as fh:
        for case in args.cases:
            row = measure(args.cache / case)
            print(json.dumps(row), flush=True)
            fh.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
