"""Getting a robot unstuck: stall detection from its commands and its motion, and recoveries
(driving straight away from where it is stuck)."""

from __future__ import annotations

from collections import deque

import numpy as np

from mrslam_core.control.config import ControlConfig


class Recovery:
    """Per robot: its recent commands and motion (``stall_time``), and the recovery it drives
    (``recovery_time`` at ``recovery_speed``, see :class:`ControlConfig`). Poses are (x, y, θ)
    [m, rad] in the map frame."""

    def __init__(self, config: ControlConfig):
        self.config = config
        #: per robot, the time its recovery ends [s]
        self.until: dict[str, float] = {}
        #: per robot, the direction of its last recovery (−1 backward, +1 forward) and its (x, y)
        #: [m] when the recovery began
        self.last: dict[str, tuple[float, np.ndarray]] = {}
        #: per robot, recent (time [s], x, y, commanded v [m/s]) for the stall check
        self.motion: dict[str, deque] = {}
        #: robots commanded forward that did not follow (``stall_time``)
        self.stalls = 0
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

    def record(self, name: str, pose: np.ndarray, v: float, now: float) -> None:
        """Note ``name``'s ``pose`` and commanded ``v`` [m/s] at ``now`` [s]; entries older than
        ``stall_time`` are dropped (the one spanning it is kept)."""
        track = self.motion.setdefault(name, deque())
        track.append((now, *np.asarray(pose, float)[:2], v))
        while len(track) > 2 and track[1][0] <= now - self.config.stall_time:
            track.popleft()

    def stalled(self, name: str, poses: dict[str, np.ndarray], now: float) -> tuple[bool, np.ndarray | None]:
        """Whether ``name`` was commanded forward for ``stall_time`` and did not follow (at least
        0.1 m/s on average commanded, less than a quarter of it covered), and where it touched
        what stopped it: (x, y) [m] ``bumper_range`` ahead of it, or None when it stands against
        another robot of ``poses`` (it has not found a wall)."""
        cfg = self.config
        track = self.motion.get(name)
        if cfg.stall_time <= 0 or not track or now - track[0][0] < cfg.stall_time:
            return False, None
        t = np.array([e[0] for e in track] + [now])
        v = np.array([e[3] for e in track])
        commanded = float(np.sum(np.maximum(v, 0.0) * np.diff(t)))
        pose = np.asarray(poses[name], float)
        moved = float(np.hypot(*(pose[:2] - np.array(track[0][1:3]))))
        if commanded < 0.1 * (now - track[0][0]) or moved >= 0.25 * commanded:
            return False, None
        self.stalls += 1
        track.clear()
        reach = cfg.platform.bumper_range
        # a robot pressing against another robot has not found a wall
        if any(np.hypot(*(np.asarray(poses[o])[:2] - pose[:2])) < 2 * reach + 0.2 for o in poses if o != name):
            return True, None
        return True, pose[:2] + reach * np.array([np.cos(pose[2]), np.sin(pose[2])])
