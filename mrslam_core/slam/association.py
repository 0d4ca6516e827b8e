"""Per-particle data association on scored observation/landmark pairs.

The filter scores V (observation, candidate slot) pairs in every particle; these functions pick,
per particle, at most one slot per observation and one observation per slot:

* :func:`associate_ml` — 000 section 5: among the candidates under the Mahalanobis gate D0, the one
  of least descriptor distance E (already ≤ E0); else a new landmark. Greedy per observation, so
  two observations may want one landmark; the cheaper keeps it.
* :func:`associate_hungarian` — 001 section III-C: a global assignment per particle
  (``scipy.optimize.linear_sum_assignment``) that maximises the joint likelihood, with one "new
  landmark" column per observation at likelihood P_new.

Both return ``pair`` (M, B): the index of the chosen pair in 0..V−1, or −1 (no landmark).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

from mrslam_core.slam.association_kernels import cheapest

_BIG = 1e12


def associate_ml(
    cost: np.ndarray, vb: np.ndarray, vc: np.ndarray, num_obs: int, width: int
) -> np.ndarray:
    """Greedy association: each observation takes its cheapest feasible pair.

    Args:
        cost: (M, V) cost of each pair, inf where infeasible (lower is better).
        vb, vc: (V,) observation index and candidate column of each pair.
        num_obs: B.
        width: C, candidate columns per observation (vc < C).

    Returns:
        pair (M, B), −1 where no pair is feasible; conflicts (one slot chosen by two
        observations of one particle) are NOT resolved here, see :func:`resolve_conflicts`.
    """
    pair = np.full((cost.shape[0], num_obs), -1, np.int64)
    cheapest(np.ascontiguousarray(cost, float), np.ascontiguousarray(vb, np.int64),
             np.ascontiguousarray(vc, np.int64), pair)
    return pair


def resolve_conflicts(pair: np.ndarray, vslots: np.ndarray, cost: np.ndarray) -> tuple[np.ndarray, int]:
    """Within a particle, a slot keeps only its cheapest observation; the others get −1.

    Returns:
        (pair (M, B), number of pairs dropped).
    """
    mi, bi = np.nonzero(pair >= 0)
    if mi.size == 0:
        return pair, 0
    pv = pair[mi, bi]
    slots = vslots[pv]
    order = np.lexsort((cost[mi, pv], slots, mi))
    mi_s, sl_s = mi[order], slots[order]
    dup = np.zeros(order.size, bool)
    dup[1:] = (mi_s[1:] == mi_s[:-1]) & (sl_s[1:] == sl_s[:-1])
    if not dup.any():
        return pair, 0
    pair = pair.copy()
    pair[mi[order][dup], bi[order][dup]] = -1
    return pair, int(dup.sum())


def associate_hungarian(
    log_lik: np.ndarray, vb: np.ndarray, vslots: np.ndarray, log_p_new: np.ndarray
) -> np.ndarray:
    """Global nearest-neighbour association per particle (Hungarian algorithm).

    Each particle's cost matrix has one row per observation and one column per candidate slot of
    the batch plus one "new" column per observation: cost −log p for feasible pairs,
    −log P_new on the observation's own "new" column, and a prohibitive cost elsewhere.

    Args:
        log_lik: (M, V) log likelihood of each pair, −inf where infeasible.
        vb: (V,) observation index of each pair.
        vslots: (V,) slot of each pair.
        log_p_new: (B,) log P_new of each observation.

    Returns:
        pair (M, B), −1 where the observation is best explained as new.
    """
    m = log_lik.shape[0]
    b = log_p_new.size
    uniq, col = np.unique(vslots, return_inverse=True)
    u = uniq.size
    pair = np.full((m, b), -1, np.int64)
    if u == 0:
        return pair
    cost = np.full((m, b, u + b), _BIG)
    cost[:, vb, col] = np.where(np.isfinite(log_lik), -log_lik, _BIG)
    cost[:, np.arange(b), u + np.arange(b)] = -log_p_new[None, :]
    lookup = np.full((b, u), -1, np.int64)
    lookup[vb, col] = np.arange(vb.size)
    feasible = np.isfinite(log_lik).any(axis=1)
    for p in np.flatnonzero(feasible):  # scipy solves one matrix per call
        rows, cols = linear_sum_assignment(cost[p])
        chosen = cols < u
        rows, cols = rows[chosen], cols[chosen]
        ok = cost[p, rows, cols] < _BIG
        pair[p, rows[ok]] = lookup[rows[ok], cols[ok]]
    return pair
