"""Pure-pursuit path following: the (v, ω) that steers a unicycle onto a path."""

from __future__ import annotations

import numpy as np

from mrslam_core.geometry.se2 import wrap_angle


def pure_pursuit(pose: np.ndarray, path_xy: np.ndarray, lookahead: float, max_speed: float,
                 max_turn_rate: float, keep_arc: bool = False) -> tuple[float, float, int]:
    """(v [m/s], ω [rad/s], index of the path point aimed at) for a robot at ``pose`` (x, y, θ)
    [m, rad] to follow ``path_xy`` (N, 2) [m], both in one frame.

    Aims at the first path point at least ``lookahead`` [m] away beyond the closest one; turns on
    the spot while that point is more than 60° off the heading. Where the arc to that point is
    tighter than ``max_speed / max_turn_rate``, the turn rate is clipped and the robot swings wide
    (0.7 m radius at 0.35 m/s and 0.5 rad/s); with ``keep_arc`` the speed is lowered instead so
    that it drives that arc (regulated pure pursuit).
    """
    d = np.linalg.norm(path_xy - pose[:2], axis=1)
    nearest = int(np.argmin(d))
    ahead = np.flatnonzero(d[nearest:] >= lookahead)
    idx = nearest + int(ahead[0]) if ahead.size else len(path_xy) - 1
    dx, dy = path_xy[idx] - pose[:2]
    bearing = float(wrap_angle(np.arctan2(dy, dx) - pose[2]))
    dist = float(np.hypot(dx, dy))
    if abs(bearing) > np.pi / 3:
        return 0.0, float(np.clip(2.0 * bearing, -max_turn_rate, max_turn_rate)), idx
    v = max_speed * min(1.0, dist / max(lookahead, 1e-6)) * np.cos(bearing)
    curvature = 2.0 * np.sin(bearing) / max(dist, 1e-6)
    if keep_arc and abs(v * curvature) > max_turn_rate:
        v = max_turn_rate / abs(curvature)
    return float(v), float(np.clip(v * curvature, -max_turn_rate, max_turn_rate)), idx
