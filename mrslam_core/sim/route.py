"""A closed route (:class:`RouteConfig`) the simulated robots drive on their own, steered by their true pose.

For runs that must repeat exactly whatever the estimates do (fault tests, benchmarks): the
robots' motion, hence every image, is the same in two runs, and only what the mapping side
does differs. Exploration steers by the estimates and cannot give that.
"""

from __future__ import annotations

import numpy as np

from mrslam_core.control.pursuit import pure_pursuit
from mrslam_core.sim.config import RouteConfig


class RouteDriver:
    """(v, ω) that keeps a robot on the loop of ``cfg``.

    Args:
        cfg: the route (non-empty).
        spacing: the loop is resampled every ``spacing`` metres [m].
    """

    def __init__(self, cfg: RouteConfig, spacing: float = 0.05):
        corners = np.asarray(cfg.waypoints, float).reshape(-1, 2)
        ends = np.roll(corners, -1, axis=0)
        pieces = []
        for a, b in zip(corners, ends):
            n = max(1, int(np.ceil(np.linalg.norm(b - a) / spacing)))
            pieces.append(a + (b - a) * (np.arange(n) / n)[:, None])
        self.cfg = cfg
        #: (N, 2) the loop, resampled [m]
        self.loop = np.concatenate(pieces)

    def command(self, pose: np.ndarray) -> tuple[float, float]:
        """(v [m/s], ω [rad/s]) for a robot at true pose (3,) (x, y, θ) [m, rad]."""
        nearest = int(np.argmin(np.linalg.norm(self.loop - pose[:2], axis=1)))
        ahead = np.roll(self.loop, -nearest, axis=0)
        v, w, _ = pure_pursuit(pose, ahead, self.cfg.lookahead, self.cfg.speed, self.cfg.turn_rate)
        return v, w
