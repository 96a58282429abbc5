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
    rows: IntArray, cols: IntArray, score: FloatArray, chosen: BoolArray, n_rows: int, n_cols: int, margin: float
) -> BoolArray:
    """Chosen edges with another edge at one of their ends scoring at most ``margin`` more.

    Returns a mask over the edges (True only on chosen ones)."""
    at_row = np.full(n_rows, -1)
    at_col = np.full(n_cols, -1)
    idx = np.flatnonzero(chosen)
    at_row[rows[idx]] = idx
    at_col[cols[idx]] = idx
    flagged = np.zeros(rows.size, dtype=bool)
    other = np.flatnonzero(~chosen)
    for owner in (at_row[rows[other]], at_col[cols[other]]):
        has = owner >= 0
        close = has & (score[other] <= np.where(has, score[owner], np.inf) + margin)
        flagged[owner[close]] = True
    return flagged
