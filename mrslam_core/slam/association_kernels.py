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
