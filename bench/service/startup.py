"""How fast the CLI and the package start: ``tumblescan --help``, ``import tumblescan`` and
``tumblescan kinds``, each in a fresh interpreter (median and worst of several runs), and
which heavy libraries each loads. Target: ``--help`` <= 0.5 s.

Usage: python -m bench.service.startup [--runs 10]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time

from ..common import machine, table

HEAVY = ("scipy", "open3d", "cv2", "gtsam", "plotly", "sqlalchemy", "fastapi", "matplotlib")
CASES = {
    "tumblescan --help": [sys.executable, "-m", "tumblescan", "--help"],
    "import tumblescan": [sys.executable, "-c", "import tumblescan"],
    "tumblescan kinds": [sys.executable, "-m", "tumblescan", "kinds"],
}


def heavy_loaded(statement: str) -> str:
    code = f"{statement}\nimport sys\nprint(' '.join(m for m in {HEAVY!r} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    return out or "none"


def time_command(cmd: list[str], runs: int) -> list[float]:
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        subprocess.run(cmd, capture_output=True, check=True)
        times.append(time.perf_counter() - t0)
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=10)
    args = parser.parse_args()
    print(machine())
    loads = {
        "tumblescan --help": heavy_loaded("import sys; sys.argv = ['tumblescan', '--help']\nimport tumblescan.cli"),
        "import tumblescan": heavy_loaded("import tumblescan"),
        "tumblescan kinds": heavy_loaded("import tumblescan.jobs.registry as r; r.kinds()"),
    }
    rows = []
    for name, cmd in CASES.items():
        t = time_command(cmd, args.runs)
        rows.append([name, f"{statistics.median(t):.3f}", f"{max(t):.3f}", loads[name]])
    print(table(rows, ["command", "median (s)", "worst (s)", "heavy libraries loaded"]))


if __name__ == "__main__":
    main()
