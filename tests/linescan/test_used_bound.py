"""The used-hits bench (``bench/linescan/used_bound.py``): the bound of a set of hits over the
bound of all of them, for sets that grow."""

from __future__ import annotations

from itertools import pairwise

import numpy as np
from bench.linescan.used_bound import PARAMS, SETS, hit_sets

from tumblescan import Scanner, Scene

from ..conftest import motion_for


def test_the_sets_grow_and_their_bound_falls_to_that_of_every_hit() -> None:
    scene = Scene(scanner=Scanner(lines=160, pixels=160))
    sets, ratios = hit_sets(motion_for(1, distance_m=50.0), scene, 1)
    assert list(sets) == list(SETS)
    shares = [float(hits.mean()) for hits in sets.values()]
    # Each set holds the one before it; the planar surfels hold most hits, every hit is the last.
    for small, large in pairwise(sets.values()):
        assert np.all(large[small])
    assert 0.5 < shares[0] < shares[-1] == 1.0
    for p in PARAMS:
        ratio = [ratios[f"{label}: {p}"] for label in SETS]
        # Fewer hits, a larger bound: never below every hit's, and falling as the sets grow.
        assert ratio[-1] == 1.0 and ratio[0] > 1.05
        assert all(a >= b - 1e-9 for a, b in pairwise(ratio))
