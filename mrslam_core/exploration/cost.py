"""Travel cost by deterministic value iteration (002 section V-A, Burgard et al. 2005).

V(x₀) = 0 at the robot's cell; V(x) = min over 8-neighbours x' of V(x') + P(x)·‖x − x'‖, where
stepping INTO cell x costs its occupancy probability times the step length; cells with
P > occ_max are not traversable. This is a shortest-path problem with non-negative weights, so
the fixed point is computed with scipy's Dijkstra on the 8-connected grid graph (the same
quantity as iterating the update rule; :func:`value_iteration_reference` iterates it directly
and the tests compare the two).
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

_NEIGHBOURS = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]


def grid_graph(prob: np.ndarray, occ_max: float, resolution: float) -> csr_matrix:
    """Directed graph over cells: edge u→v of weight P(v)·|u−v| for 8-neighbours, v traversable."""
    h, w = prob.shape
    idx = np.arange(h * w).reshape(h, w)
    ok = prob <= occ_max
    rows, cols, vals = [], [], []
    for di, dj in _NEIGHBOURS:
        rs, rd = slice(max(0, -di), h - max(0, di)), slice(max(0, di), h - max(0, -di))
        cs, cd = slice(max(0, -dj), w - max(0, dj)), slice(max(0, dj), w - max(0, -dj))
        src, dst, pv, okv = idx[rs, cs], idx[rd, cd], prob[rd, cd], ok[rd, cd]
        step = resolution * (np.sqrt(2.0) if di and dj else 1.0)
        rows.append(src[okv])
        cols.append(dst[okv])
        vals.append(np.maximum(pv[okv], 1e-6) * step)  # explicit zeros would drop the edge
    return csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(h * w, h * w))


def travel_cost(prob: np.ndarray, sources: np.ndarray, occ_max: float, resolution: float) -> np.ndarray:
    """V for each source cell: (S, H, W), inf where unreachable."""
    graph = grid_graph(prob, occ_max, resolution)
    flat = sources[:, 0] * prob.shape[1] + sources[:, 1]
    dist = dijkstra(graph, directed=True, indices=flat)
    return dist.reshape(len(sources), *prob.shape)


def value_iteration_reference(prob: np.ndarray, source: tuple[int, int], occ_max: float, resolution: float) -> np.ndarray:
    """The update rule of 002 V-A iterated to its fixed point (slow; for tests)."""
    h, w = prob.shape
    v = np.full((h, w), np.inf)
    v[source] = 0.0
    while True:
        old = v.copy()
        for di, dj in _NEIGHBOURS:
            step = resolution * (np.sqrt(2.0) if di and dj else 1.0)
            shifted = np.full((h, w), np.inf)
            shifted[max(0, di): h + min(0, di), max(0, dj): w + min(0, dj)] = old[max(0, -di): h - max(0, di), max(0, -dj): w - max(0, dj)]
            cand = shifted + np.maximum(prob, 1e-6) * step
            v = np.where(prob <= occ_max, np.minimum(v, cand), v)
        v[source] = 0.0
        if np.array_equal(v, old):
            return v
