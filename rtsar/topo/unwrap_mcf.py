"""Minimum-cost-flow phase unwrapping (Costantini 1998), solved by OR-tools.

Costantini, "A novel phase unwrapping method based on network programming", IEEE TGRS 36(3), 1998.
Unknowns: an integer number of cycles ``k`` added to every wrapped gradient (row and column
gradients of ``rtsar.topo.phase.wrapped_gradients``).  The corrected field ``Δ + 2πk`` must be
irrotational: around every elementary loop the corrections cancel the residue,
``k_col[i,j] + k_row[i,j+1] − k_col[i+1,j] − k_row[i,j] = −r[i,j]``.  Each gradient sits between two
loops (or one loop and the outside of the grid), so these constraints are flow conservation on the
dual graph: nodes are the loops plus one earth node for the border, every gradient gives two
opposite arcs carrying ``k⁺`` and ``k⁻`` (``k = k⁺ − k⁻``), a loop of residue r supplies ``−r``
units and the earth balances the total.  The objective ``Σ c |k|`` is minimised with
``ortools.graph.python.min_cost_flow.SimpleMinCostFlow``; the corrected gradients are then
integrated.  The result is congruent with the data (``φ − ψ ∈ 2πℤ``) and its errors stay where the
residues are.

Costs: the same for every gradient without weights; with pixel weights w (e.g. coherence) the cost
of a gradient is ``round(100 · min(w_a, w_b) / max w)`` (at least 1 where the weight is positive),
so corrections are placed where the data are poor.  A gradient touching an invalid (masked) or
zero-weight pixel costs 0: discontinuities pass through such areas freely.  Dual nodes joined by
free gradients are merged before solving, and the phase is then integrated along a spanning forest
of the positive-cost gradients only (``integrate_cycles_on``).
"""

from __future__ import annotations

import numpy as np

from ..phase import TWO_PI
from .phase import residues, wrapped_gradients

COST_SCALE = 100  # integer cost of a full-weight gradient; OR-tools needs integer costs


def dual_graph(rows: int, cols: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Arcs of the dual graph for ``k > 0`` on each gradient: ``(row_tail, row_head, col_tail,
    col_head)``, each shaped like its gradient array.  Loop ``(i, j)`` is node ``i·(cols−1) + j``;
    the earth is node ``(rows−1)·(cols−1)``.

    Costantini 1998 (dual network of the grid): a row gradient ``(i, j) → (i+1, j)`` enters the
    loop on its left, ``(i, j−1)``, with sign +1 and the loop on its right, ``(i, j)``, with sign
    −1, so ``k_row > 0`` flows left → right; a column gradient ``(i, j) → (i, j+1)`` enters loop
    ``(i, j)`` with +1 and loop ``(i−1, j)`` with −1, so ``k_col > 0`` flows from the loop below to
    the loop above.
    """
    earth = (rows - 1) * (cols - 1)
    loop = np.arange(earth).reshape(rows - 1, cols - 1)
    row_tail = np.full((rows - 1, cols), earth)
    row_head = np.full((rows - 1, cols), earth)
    row_tail[:, 1:] = loop  # left loop (i, j − 1)
    row_head[:, :-1] = loop  # right loop (i, j)
    col_tail = np.full((rows, cols - 1), earth)
    col_head = np.full((rows, cols - 1), earth)
    col_tail[:-1, :] = loop  # loop below (i, j)
    col_head[1:, :] = loop  # loop above (i − 1, j)
    return row_tail, row_head, col_tail, col_head


def gradient_costs(
    shape: tuple[int, int], mask: np.ndarray | None, weights: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """Integer cost per cycle of correction on each row and column gradient (module docstring)."""
    w = np.ones(shape) if weights is None else np.asarray(weights, dtype=np.float64).copy()
    if mask is not None:
        w[~mask] = 0.0
    w_row = np.minimum(w[1:, :], w[:-1, :])
    w_col = np.minimum(w[:, 1:], w[:, :-1])
    top = max(float(w_row.max(initial=0.0)), float(w_col.max(initial=0.0)))
    if top == 0.0:
        return np.zeros(w_row.shape, np.int64), np.zeros(w_col.shape, np.int64)
    costs = []
    for we in (w_row, w_col):
        c = np.rint(COST_SCALE * we / top).astype(np.int64)
        c[(we > 0.0) & (c == 0)] = 1
        costs.append(c)
    return costs[0], costs[1]


def cycle_corrections(
    charge: np.ndarray, cost_row: np.ndarray, cost_col: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Integer corrections ``(k_row, k_col)`` of least total cost that cancel every residue.

    Costantini 1998 (the minimum-cost-flow problem on the dual graph), solved by OR-tools'
    SimpleMinCostFlow.  ``charge`` is ``residues(ψ)`` [rows − 1, cols − 1].  Dual nodes joined by a
    zero-cost gradient (one touching an invalid pixel) are merged first: flow moves between them for
    free, and the push-relabel solver is slow on large zero-cost plateaus.  Gradients of zero cost
    get ``k = 0`` and are not irrotational; integrate over positive-cost gradients only.
    """
    rows, cols = charge.shape[0] + 1, charge.shape[1] + 1
    k_row = np.zeros((rows - 1, cols), np.int64)
    k_col = np.zeros((rows, cols - 1), np.int64)
    total = int(np.abs(charge).sum())
    if total == 0:
        return k_row, k_col
    from ortools.graph.python import min_cost_flow

    row_tail, row_head, col_tail, col_head = dual_graph(rows, cols)
    tails = np.concatenate([row_tail.ravel(), col_tail.ravel()])
    heads = np.concatenate([row_head.ravel(), col_head.ravel()])
    costs = np.concatenate([cost_row.ravel(), cost_col.ravel()]).astype(np.int64)
    supply = np.append(-charge.ravel().astype(np.int64), int(charge.sum()))
    node = _merge_free_nodes(tails, heads, costs == 0, supply.size)
    tails, heads = node[tails], node[heads]
    keep = np.flatnonzero((costs > 0) & (tails != heads))  # a self-loop never carries flow
    supply = np.bincount(node, weights=supply, minlength=node.max() + 1).astype(np.int64)
    solver = min_cost_flow.SimpleMinCostFlow()
    # Arcs 0 … n−1 carry k⁺ (tail → head), arcs n … 2n−1 carry k⁻ (head → tail).
    n = keep.size
    solver.add_arcs_with_capacity_and_unit_cost(
        np.concatenate([tails[keep], heads[keep]]).astype(np.int32),
        np.concatenate([heads[keep], tails[keep]]).astype(np.int32),
        np.full(2 * n, total, np.int64),
        np.concatenate([costs[keep], costs[keep]]),
    )
    solver.set_nodes_supplies(np.arange(supply.size, dtype=np.int32), supply)
    status = solver.solve()
    if status != solver.OPTIMAL:
        raise RuntimeError(f"OR-tools min-cost flow failed with status {status}")
    flow = solver.flows(np.arange(2 * n, dtype=np.int32))
    k = np.zeros(costs.size, np.int64)
    k[keep] = flow[:n] - flow[n:]
    k_row[:] = k[: k_row.size].reshape(k_row.shape)
    k_col[:] = k[k_row.size :].reshape(k_col.shape)
    return k_row, k_col


def _merge_free_nodes(tails, heads, free, n_nodes: int) -> np.ndarray:
    """New node index of every dual node after merging those joined by free (zero-cost) arcs."""
    if not free.any():
        return np.arange(n_nodes)
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    graph = coo_matrix(
        (np.ones(int(free.sum())), (tails[free], heads[free])), shape=(n_nodes, n_nodes)
    )
    return connected_components(graph, directed=False)[1]


def integrate_cycles(n_row: np.ndarray, n_col: np.ndarray) -> np.ndarray:
    """Integer cycle map K from irrotational integer gradients, ``K[0, 0] = 0`` (int64).

    Down the first column, then along every row; any other path gives the same K because the
    corrected gradients have no residues left.
    """
    rows, cols = n_col.shape[0], n_row.shape[1]
    k = np.zeros((rows, cols), np.int64)
    k[1:, 0] = np.cumsum(n_row[:, 0])
    k[:, 1:] = k[:, :1] + np.cumsum(n_col, axis=1)
    return k


def integrate_cycles_on(
    n_row: np.ndarray,
    n_col: np.ndarray,
    sure_row: np.ndarray,
    sure_col: np.ndarray,
    valid: np.ndarray,
) -> np.ndarray:
    """Integer cycle map K over the valid pixels, integrating along a spanning forest (int64).

    The forest is a minimum spanning tree of the valid-to-valid gradients in which the "sure" ones
    (positive cost, hence irrotational after ``cycle_corrections``) weigh 1 and the others 2, so
    pixels joined by sure gradients are joined through sure gradients only and their K does not
    depend on the tree.  The root of every connected piece gets K = 0.  Sums along the tree are
    formed by pointer jumping (log₂ of the depth vectorised steps).  Invalid pixels get 0.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import (
        breadth_first_order,
        connected_components,
        minimum_spanning_tree,
    )

    rows, cols = valid.shape
    n_pix = rows * cols
    idx = np.arange(n_pix).reshape(rows, cols)
    use_row = valid[:-1, :] & valid[1:, :]
    use_col = valid[:, :-1] & valid[:, 1:]
    a = np.concatenate([idx[:-1, :][use_row], idx[:, :-1][use_col]])
    b = np.concatenate([idx[1:, :][use_row], idx[:, 1:][use_col]])
    w = np.concatenate(
        [np.where(sure_row[use_row], 1.0, 2.0), np.where(sure_col[use_col], 1.0, 2.0)]
    )
    graph = coo_matrix((w, (a, b)), shape=(n_pix, n_pix)).tocsr()
    tree = minimum_spanning_tree(graph).tocoo()
    _, piece = connected_components(graph, directed=False)
    roots = np.unique(piece, return_index=True)[1]
    top = n_pix  # a virtual node joined to one root per piece
    forest = coo_matrix(
        (
            np.concatenate([tree.data, np.ones(roots.size)]),
            (
                np.concatenate([tree.row, np.full(roots.size, top)]),
                np.concatenate([tree.col, roots]),
            ),
        ),
        shape=(n_pix + 1, n_pix + 1),
    ).tocsr()
    _, pred = breadth_first_order(forest, top, directed=False, return_predecessors=True)
    parent = np.append(pred[:n_pix], top)
    v = np.arange(n_pix)
    p = parent[:n_pix]
    step = np.where(p == top, 0, v - p)  # 0: a root, joined to the virtual node
    inc = np.zeros(n_pix + 1, np.int64)
    down, up = step == cols, step == -cols
    right, left = step == 1, step == -1
    inc[:n_pix][down] = n_row.ravel()[p[down]]  # parent above: n_row at the parent
    inc[:n_pix][up] = -n_row.ravel()[v[up]]
    n_col_full = np.zeros((rows, cols), np.int64)
    n_col_full[:, :-1] = n_col
    inc[:n_pix][right] = n_col_full.ravel()[p[right]]
    inc[:n_pix][left] = -n_col_full.ravel()[v[left]]
    while (parent != top).any():
        inc = inc + inc[parent]
        parent = parent[parent]
    k = inc[:n_pix].reshape(rows, cols)
    k[~valid] = 0
    return k


def unwrap_min_cost_flow(
    psi: np.ndarray, mask: np.ndarray | None = None, weights: np.ndarray | None = None
) -> np.ndarray:
    """Costantini unwrapping of a checked float64 phase (call ``rtsar.topo.unwrap.unwrap``).

    ``psi`` must already hold a finite value on every pixel (invalid ones set to anything, e.g. 0);
    the output is ``ψ + 2πK`` with K integer, so it is congruent with ``psi`` everywhere.
    """
    d_row, d_col = wrapped_gradients(psi)
    cost_row, cost_col = gradient_costs(psi.shape, mask, weights)
    k_row, k_col = cycle_corrections(residues(psi), cost_row, cost_col)
    # Cycles between neighbouring samples: the wrap applied by W, plus the correction.
    n_row = np.rint((d_row - np.diff(psi, axis=0)) / TWO_PI).astype(np.int64) + k_row
    n_col = np.rint((d_col - np.diff(psi, axis=1)) / TWO_PI).astype(np.int64) + k_col
    if (cost_row > 0).all() and (cost_col > 0).all():
        return psi + TWO_PI * integrate_cycles(n_row, n_col)
    valid = np.ones(psi.shape, bool) if mask is None else mask
    return psi + TWO_PI * integrate_cycles_on(n_row, n_col, cost_row > 0, cost_col > 0, valid)
