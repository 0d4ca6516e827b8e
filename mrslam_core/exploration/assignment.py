"""Target assignment: utility discounted near assigned targets (002 eq. 8–9), the robots in
turn (002)."""

from __future__ import annotations

import numpy as np


def assign_targets(
    targets_xy: np.ndarray, cost: np.ndarray, beta: float, utility_range: float, coordinated: bool = True,
) -> np.ndarray:
    """Choose one target per robot.

    Coordinated, robot n takes argmax U(t | t₁…tₙ₋₁) − β·V_t^n after robots 1…n−1 (002 eq. 8,
    the robots in list order); the utility of targets within ``utility_range`` of each assigned
    one is then discounted (eq. 9).

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
    chosen = np.full(k, -1, np.int64)
    if t == 0:
        return chosen
    utility = np.ones(t)
    reachable = np.isfinite(cost)
    if not coordinated:
        score = np.where(reachable, utility - beta * np.where(reachable, cost, 0.0), -np.inf)
        ok = reachable.any(axis=1)
        chosen[ok] = np.argmax(score[ok], axis=1)
        return chosen
    open_ = reachable.any(axis=1)
    while open_.any():
        score = np.where(reachable & open_[:, None], utility - beta * np.where(reachable, cost, 0.0), -np.inf)
        i = int(np.flatnonzero(open_)[0])
        j = int(np.argmax(score[i]))
        chosen[i] = j
        open_[i] = False
        d = np.linalg.norm(targets_xy - targets_xy[j], axis=1)
        utility -= np.where(d < utility_range, 1.0 - d / utility_range, 0.0)
    return chosen
