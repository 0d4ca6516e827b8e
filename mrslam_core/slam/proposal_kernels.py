"""Compiled kernel of the FastSLAM 2.0 proposal (:meth:`MultiRobotFastSLAM._combine
<mrslam_core.slam.filter.MultiRobotFastSLAM>`): sums of per-pair terms by particle.

``np.bincount`` with weights, once per column, did this before; the loop adds in the same order
(pair by pair), so the sums are bit for bit the same.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def sum_by(index, values, n):
    """Row sums of ``values`` (P, C) grouped by ``index`` (P,) into (n, C)."""
    out = np.zeros((n, values.shape[1]))
    for i in range(index.size):
        for c in range(values.shape[1]):
            out[index[i], c] += values[i, c]
    return out
