"""Target assignment: utility discounted near assigned targets (002 eq. 8–9), robots in turn."""

from __future__ import annotations

import numpy as np


def assign_targets(
    targets_xy: np.ndarray, cost: np.ndarray, beta: float, utility_range: float, coordinated: bool = True
) -> np.ndarray:
    """Choose one target per robot.

    Args:
        targets_xy: (T, 2) candidate target positions [m].
        cost: (K, T) travel cost of each robot to each target (inf: unreachable).
        beta: weight of the cost.
        utility_range: max_range of P(d) = 1 − d/max_range [m].
        coordinated: discount the utility after each assignment (else every robot ignores the
            others and may pick the same target).

    Returns:
        (K,) index of each robot's target, −1 where no target is reachable.
    """
    k, t = cost.shape
    utility = np.ones(t)
    chosen = np.full(k, -1, np.int64)
    for i in range(k):
        score = utility - beta * cost[i]
        score[~np.isfinite(cost[i])] = -np.inf
        if not np.isfinite(score).any():
            continue
        j = int(np.argmax(score))
        chosen[i] = j
        if coordinated:
            d = np.linalg.norm(targets_xy - targets_xy[j], axis=1)
            utility -= np.where(d < utility_range, 1.0 - d / utility_range, 0.0)
    return chosen
