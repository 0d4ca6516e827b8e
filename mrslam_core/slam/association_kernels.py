"""Compiled kernel of the filter's maximum-likelihood association: the cost of every particle's
candidate pairs in one pass (numpy built it with a dozen (M, V) temporaries).

The rule is :class:`~mrslam_core.slam.config.AssociationConfig`'s; the arithmetic is the numpy
code's, so costs are bit for bit the same. The choice per observation is
:func:`~mrslam_core.slam.association.associate_ml`'s.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def ml_cost(maha, held, confirmed, ev, gate, weight, trust_gate, track_slot, vslots, vb, track_gate, cost):
    """Cost (lower is better, inf: infeasible) of each particle's candidate pairs.

    A pair is feasible when the particle holds the landmark and D ≤ ``gate`` (D0); its cost is
    E + ``weight``·D, plus 10³ when the landmark is not confirmed yet (landmarks first). With
    ``trust_gate`` > D0, a held pair that fails D0 but has D ≤ ``trust_gate`` costs 10⁶ + D
    (chosen only where nothing passes D0). With a track memory (``track_slot`` (M, B), else
    (0, 0)), a held pair with D ≤ ``track_gate`` whose slot the observation's track went to in
    this particle costs −1 (a continuing track keeps its landmark).

    Args:
        maha, held, confirmed: (M, V) D, held and confirmed of each pair.
        ev: (V,) descriptor distance E of each pair; vslots, vb: (V,) its slot and observation.
        cost: (M, V) output.
    """
    use_trust = trust_gate > gate
    use_track = track_slot.shape[0] > 0
    for m in range(maha.shape[0]):
        for v in range(maha.shape[1]):
            d = maha[m, v]
            h = held[m, v]
            feasible = h and d <= gate
            c = ev[v] + weight * d if feasible else np.inf
            if feasible and not confirmed[m, v]:
                c = c + 1e3
            if use_trust and h and not feasible and d <= trust_gate:
                c = 1e6 + d
            if use_track and h and vslots[v] == track_slot[m, vb[v]] and d <= track_gate:
                c = -1.0
            cost[m, v] = c


@njit(cache=True)
def cheapest(cost, vb, vc, pair):
    """Per particle and observation the pair of least cost, as ``argmin`` over the observation's
    candidate columns picks it: the lowest column among equal costs; −1 where the least cost is
    not finite or a cost is NaN (argmin's NaN wins and fails the finiteness test).

    Args:
        cost: (M, V) cost of each pair; vb, vc: (V,) its observation and candidate column
            (distinct pairs).
        pair: (M, B) output, −1 on entry.
    """
    num_obs = pair.shape[1]
    best = np.empty(num_obs)
    col = np.empty(num_obs, np.int64)
    nan = np.empty(num_obs, np.bool_)
    for m in range(cost.shape[0]):
        best[:] = np.inf
        col[:] = -1
        nan[:] = False
        for v in range(cost.shape[1]):
            c = cost[m, v]
            b = vb[v]
            if c != c:
                nan[b] = True
            elif c < best[b] or (c == best[b] and vc[v] < col[b]):
                best[b] = c
                col[b] = vc[v]
                pair[m, b] = v
        for b in range(num_obs):
            if nan[b] or not np.isfinite(best[b]):
                pair[m, b] = -1


@njit(cache=True)
def chosen(pair, vslots, confirmed, rows):
    """The associated (particle, observation) pairs of ``pair`` (M, B) (≥ 0: the chosen pair v),
    in row-major order as ``np.nonzero`` lists them, with what the update needs of each.

    Args:
        vslots: (V,) slot of pair v; confirmed: (M, V) bool; rows: (M, V) pool row of each pair.

    Returns:
        (particle, observation, slot, confirmed, pool row), each (P,).
    """
    n = 0
    for m in range(pair.shape[0]):
        for b in range(pair.shape[1]):
            n += pair[m, b] >= 0
    mi, bi = np.empty(n, np.int64), np.empty(n, np.int64)
    slots, read = np.empty(n, np.int64), np.empty(n, np.int64)
    conf = np.empty(n, np.bool_)
    i = 0
    for m in range(pair.shape[0]):
        for b in range(pair.shape[1]):
            v = pair[m, b]
            if v >= 0:
                mi[i], bi[i] = m, b
                slots[i] = vslots[v]
                conf[i] = confirmed[m, v]
                read[i] = rows[m, v]
                i += 1
    return mi, bi, slots, conf, read
