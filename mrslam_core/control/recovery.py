"""Getting a robot unstuck: recoveries (driving straight away from where it is stuck)."""

from __future__ import annotations

import numpy as np

from mrslam_core.control.config import ControlConfig


class Recovery:
    """Per robot: the recovery it drives (``recovery_time`` at ``recovery_speed``, see
    :class:`ControlConfig`). Poses are (x, y, θ) [m, rad] in the map frame."""

    def __init__(self, config: ControlConfig):
        self.config = config
        #: per robot, the time its recovery ends [s]
        self.until: dict[str, float] = {}
        #: per robot, the direction of its last recovery (−1 backward, +1 forward) and its (x, y)
        #: [m] when the recovery began
        self.last: dict[str, tuple[float, np.ndarray]] = {}
        #: recoveries of robots that could reach none of the targets from where they stood
        self.boxed_in = 0

    def start(self, name: str, pose: np.ndarray, now: float) -> None:
        """Drive ``name``, at ``pose``, straight for ``recovery_time`` from ``now`` [s], away from
        where it is stuck."""
        self.until[name] = now + self.config.recovery_time
        self.last[name] = (self._direction(name, pose), np.asarray(pose, float)[:2].copy())

    def start_boxed_in(self, name: str, pose: np.ndarray, now: float) -> None:
        """:meth:`start` for a robot that can reach no target from where it stands (counted as
        ``boxed_in``)."""
        self.boxed_in += 1
        self.start(name, pose, now)

    def active(self, name: str, now: float) -> bool:
        """Whether ``name`` is recovering at ``now`` [s]."""
        return now < self.until.get(name, -np.inf)

    def command(self, name: str) -> tuple[float, float]:
        """(v [m/s], ω [rad/s]) of ``name``'s recovery: straight, at ``recovery_speed``."""
        return self.last[name][0] * self.config.recovery_speed, 0.0

    def _direction(self, name: str, pose: np.ndarray) -> float:
        """Back off (−1), unless the last recovery did not move the robot (< 5 cm): then the other
        way. A robot whose rear corner touches a wall cannot back off along it (the wheels do not
        slip), nor turn that corner into the wall; pulling forward frees it."""
        last = self.last.get(name)
        if last is None:
            return -1.0
        direction, start = last
        if np.linalg.norm(np.asarray(pose)[:2] - start) < 0.05:
            return -direction
        return -1.0
