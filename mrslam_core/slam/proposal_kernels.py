"""Compiled kernel of the FastSLAM 2.0 proposal (:meth:`MultiRobotFastSLAM._combine
<mrslam_core.slam.filter.MultiRobotFastSLAM>`): sums of per-pair terms by particle.

``np.bincount`` with weights, once per column, did this before; the loop adds in the same order
(pair by pair), so the sums are bit for bit the same.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def sum_terms(index, info, eta, quad, norm, n):
    """Per-particle sums of the proposal's per-pair terms in one pass: ``info`` (P, 9), ``eta``
    (P, 3), ``quad`` (P,) and ``norm`` (P,) grouped by ``index`` (P,) into (n, 9), (n, 3), (n,)
    and (n,)."""
    s_info = np.zeros((n, 9))
    s_eta = np.zeros((n, 3))
    s_quad = np.zeros(n)
    s_norm = np.zeros(n)
    for i in range(index.size):
        m = index[i]
        for c in range(9):
            s_info[m, c] += info[i, c]
        for c in range(3):
            s_eta[m, c] += eta[i, c]
        s_quad[m] += quad[i]
        s_norm[m] += norm[i]
    return s_info, s_eta, s_quad, s_norm
