"""Spurious returns: ranges far from the surface their cell of the sensor's view sees.

A return metres off (multipath, a stray reflection) makes its cell fail every planarity test;
a thin boom or truss member in front of another surface is a minority of every cell it
crosses yet lies on a surface. The first is left out, the second kept.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..._typing import FloatArray, IntArray

# A return off its cell's ranges is a surface's (a thin boom in front of a panel) when this
# many others of its cell and the 8 around lie within 3 range sigmas of it.
MIN_SUPPORT = 12


def range_inliers(
    cell: IntArray, range_m: FloatArray, range_sigma_m: float, neighbours: IntArray | None = None
) -> NDArray[np.bool_]:
    """Points whose range lies within their cell's Tukey fences, widened by 3 range sigmas:
    ``[q1 - 1.5 IQR - 3 s_r, q3 + 1.5 IQR + 3 s_r]``, or that a surface supports: at least
    ``MIN_SUPPORT`` other returns of their cell and its ``neighbours`` ``(m, 8)`` lie within
    3 range sigmas of their range. A surface's own ranges, spread by its slope and by noise,
    lie inside; so does a thin boom or truss in front of a panel, a minority in every cell it
    crosses but a line of returns at one range; a return metres off (multipath, a stray
    reflection) does not. Cells of fewer than 4 points keep every point."""
    # Sorted by cell, then range: one key, the cell plus the range scaled into [0, 1) (twice as
    # fast as a two-key lexsort on a million points).
    lo_m = range_m.min()
    span = float(np.ptp(range_m)) * (1 + 1e-9) + 1e-12
    key = cell + (range_m - lo_m) / span
    order = np.argsort(key)
    counts = np.bincount(cell)
    starts = np.cumsum(counts) - counts
    sorted_range = range_m[order]
    q1 = sorted_range[starts + np.floor(0.25 * (counts - 1)).astype(np.int64)]
    q3 = sorted_range[starts + np.ceil(0.75 * (counts - 1)).astype(np.int64)]
    margin = 1.5 * (q3 - q1) + 3 * range_sigma_m
    lo, hi = (q1 - margin)[cell], (q3 + margin)[cell]
    inside = ((range_m >= lo) & (range_m <= hi)) | (counts[cell] < 4)
    out = np.flatnonzero(~inside)
    if neighbours is None or len(out) == 0:
        return np.asarray(inside)
    sorted_key = key[order]
    r, c = range_m[out], cell[out]
    near = 3 * range_sigma_m
    lo_f = np.clip((r - near - lo_m) / span, 0.0, 1 - 1e-12)
    hi_f = np.clip((r + near - lo_m) / span, 0.0, 1 - 1e-12)
    support = -np.ones(len(out))  # the point itself
    for nb in np.column_stack([c, neighbours[c]]).T:
        hit = nb >= 0
        n = nb[hit]
        support[hit] += np.searchsorted(sorted_key, n + hi_f[hit], "right") - np.searchsorted(
            sorted_key, n + lo_f[hit], "left"
        )
    inside[out[support >= MIN_SUPPORT]] = True
    return np.asarray(inside)
