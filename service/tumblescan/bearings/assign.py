"""One-to-one assignment on a sparse bipartite graph, component by component.

Edges carry a cost (negative: worth taking); a missing edge costs 0 and means "leave both
ends unassigned". Most components of a realistic graph are one edge and are decided without
a solver; the rest go to ``scipy.optimize.linear_sum_assignment``, a few components per dense matrix.
"""

from __future__ import annotations

import numpy as np

from .._typing import BoolArray, FloatArray, IntArray

BATCH_ROWS = 200


def assign_sparse(rows: IntArray, cols: IntArray, cost: FloatArray, n_rows: int, n_cols: int) -> BoolArray:
    """Which edges the minimum-cost one-to-one assignment takes (a mask over the edges).

    ``rows`` (m,) in [0, n_rows), ``cols`` (m,) in [0, n_cols), ``cost`` (m,); each (row, col)
    appears at most once. Edges with cost >= 0 are never taken.
    """
    from scipy.optimize import linear_sum_assignment
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    m = rows.size
    chosen = np.zeros(m, dtype=bool)
    if m == 0:
        return chosen
    n = n_rows + n_cols
    graph = coo_matrix((np.ones(m), (rows, cols + n_rows)), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    comp = labels[rows]
    sizes = np.bincount(comp, minlength=labels.max() + 1)
    single = sizes[comp] == 1
    chosen[single] = cost[single] < 0.0
    multi = np.flatnonzero(~single)
    if multi.size == 0:
        return chosen
    # Components are independent, and a non-edge costs the same as leaving a node out, so
    # several components can share one dense problem: batches of about BATCH_ROWS rows.
    multi = multi[np.argsort(comp[multi], kind="stable")]
    row_keys = np.unique(comp[multi].astype(np.int64) * n_rows + rows[multi])
    rows_per_comp = np.bincount(row_keys // n_rows, minlength=sizes.size)
    batch_of_comp = np.cumsum(rows_per_comp) // BATCH_ROWS
    batch = batch_of_comp[comp[multi]]
    for edges in np.split(multi, np.flatnonzero(np.diff(batch)) + 1):
        r_u, r_i = np.unique(rows[edges], return_inverse=True)
        c_u, c_i = np.unique(cols[edges], return_inverse=True)
        C = np.zeros((r_u.size, c_u.size))
        E = np.full((r_u.size, c_u.size), -1)
        C[r_i, c_i] = np.minimum(cost[edges], 0.0)
        E[r_i, c_i] = edges
        ri, ci = linear_sum_assignment(C)
        take = E[ri, ci]
        take = take[(take >= 0) & (C[ri, ci] < 0.0)]
        chosen[take] = True
    return chosen


def close_alternatives(
    rows: IntArray,
    cols: IntArray,
    chi2: FloatArray,
    chosen: BoolArray,
    n_rows: int,
    n_cols: int,
    margin: float,
    gate: float,
) -> BoolArray:
    """Chosen edges for which another assignment costs at most ``margin`` more χ².

    The alternatives tried are the ones an edge not taken opens (cost of an edge χ² − gate,
    leaving a node out 0): a swap of two chosen pairs' partners, or taking a free node in place
    of a chosen pair's partner. Returns a mask over the edges (True only on chosen ones)."""
    at_row = np.full(n_rows, -1)
    at_col = np.full(n_cols, -1)
    idx = np.flatnonzero(chosen)
    at_row[rows[idx]] = idx
    at_col[cols[idx]] = idx
    flagged = np.zeros(rows.size, dtype=bool)
    other = np.flatnonzero(~chosen)
    if other.size == 0:
        return flagged
    key = rows.astype(np.int64) * n_cols + cols
    order = np.argsort(key)
    o_r, o_c = at_row[rows[other]], at_col[cols[other]]
    both = (o_r >= 0) & (o_c >= 0)
    # Swap: (r, c) and (row of c's pair, col of r's pair) in place of the two chosen pairs.
    partner_key = np.where(both, rows[np.maximum(o_c, 0)].astype(np.int64) * n_cols + cols[np.maximum(o_r, 0)], -1)
    pos = np.clip(np.searchsorted(key[order], partner_key), 0, key.size - 1)
    found = both & (key[order][pos] == partner_key)
    partner_chi2 = np.where(found, chi2[order][pos], gate)  # no partner edge: both left out
    delta = np.full(other.size, np.inf)
    delta[both] = (chi2[other] + partner_chi2 - chi2[np.maximum(o_r, 0)] - chi2[np.maximum(o_c, 0)])[both]
    only_r = (o_r >= 0) & (o_c < 0)
    only_c = (o_c >= 0) & (o_r < 0)
    delta[only_r] = (chi2[other] - chi2[np.maximum(o_r, 0)])[only_r]
    delta[only_c] = (chi2[other] - chi2[np.maximum(o_c, 0)])[only_c]
    close = delta <= margin
    for owner in (o_r, o_c):
        hit = close & (owner >= 0)
        flagged[owner[hit]] = True
    return flagged
