"""The human-readable summary of a result (the CLI without ``--json``): the counts, then where
the targets are and how well that is known, so the sigma is seen without opening the JSON."""

from __future__ import annotations

import math
from typing import Any

from ..report.numbers import sigma_decimals

MAX_LINES = 10


def plural(n: int, word: str, words: str | None = None) -> str:
    """``1 track``, ``2 tracks`` (``words``: a plural not made with an s)."""
    return f"{n} {word}" if n == 1 else f"{n} {words or word + 's'}"


def decimals(sigma_m: list[float]) -> int:
    """Decimals that show the smallest sigma to two significant digits (0 to 6)."""
    finite = [s for s in sigma_m if math.isfinite(s) and s > 0]
    return sigma_decimals(min(finite) if finite else None, default=1)


def vector_text(v: list[float], sigma_m: list[float]) -> str:
    """``(x, y, z) ± (sx, sy, sz) m`` at the precision of the sigmas."""
    d = decimals(sigma_m)
    return f"({', '.join(f'{x:.{d}f}' for x in v)}) ± ({', '.join(f'{s:.{d}f}' for s in sigma_m)}) m"


def summary_text(result: dict[str, Any]) -> str:
    """Counts on one line; then, one line each (the first ``MAX_LINES``, then how many more),
    the fitted tracks (position at ``t_ref`` and its 1-sigma) or, without tracks, the targets
    of the first frame that has any (position and 1-sigma)."""
    s = result["summary"]
    unassoc = ", ".join(f"{k} {v}" for k, v in s["unassociated"].items())
    tracks = plural(s["tracks"], "track")
    if s.get("short_tracks"):
        tracks += f" (+{s['short_tracks']} too short to fit)"
    lines = [
        f"{plural(s['targets'], 'target')} in {plural(len(result['frames']), 'frame')} "
        f"({s['ambiguous']} ambiguous, {tracks}); unassociated detections: {unassoc}; "
        f"{result['timings_ms']['total']:.0f} ms"
    ]
    rows: list[str] = []
    if result.get("tracks"):
        lines.append("tracks, position at t_ref ± 1-sigma (job frame):")
        for tr in result["tracks"]:
            sigma = [math.sqrt(abs(tr["cov_m2"][i][i])) for i in range(3)]
            rows.append(
                f"  {tr['id']}: t_ref {tr['t_ref']:g} s, {vector_text(tr['position_m'], sigma)}, "
                f"{plural(tr['fixes_used'], 'fix', 'fixes')}"
            )
    else:
        frame = next((fr for fr in result["frames"] if fr["targets"]), None)
        if frame is not None:
            lines.append(f"frame {frame['index']} (t = {frame['t']:g} s), position ± 1-sigma (job frame):")
            rows = [f"  {t['id']}: {vector_text(t['position_m'], t['sigma_m'])}" for t in frame["targets"]]
    lines += rows[:MAX_LINES]
    if len(rows) > MAX_LINES:
        lines.append(f"  ... and {len(rows) - MAX_LINES} more (all in --json, --out and --report)")
    return "\n".join(lines)
