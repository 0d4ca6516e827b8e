"""The team's drive commands: each robot's recovery, or its path follower."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mrslam_core.control.config import ControlConfig
from mrslam_core.control.follower import Follower
from mrslam_core.control.recovery import Recovery

if TYPE_CHECKING:
    from mrslam_core.exploration.grid import OccupancyGrid


class Controller:
    """(v, ω) per robot from the paths it is given (:class:`ControlConfig`). Poses (x, y, θ) [m,
    rad] and paths (N, 2) [m] are in the map frame."""

    def __init__(self, config: ControlConfig | None = None):
        self.config = config or ControlConfig()
        self.follower = Follower(self.config)
        self.recovery = Recovery(self.config)

    def step(self, grid: OccupancyGrid, poses: dict[str, np.ndarray], paths: dict[str, np.ndarray | None],
             now: float, halt: bool = False) -> dict[str, tuple[float, float]]:
        """Commands (v [m/s], ω [rad/s]) at time ``now`` [s] for the robots of ``paths``, in its
        order: a robot recovering drives its recovery, one without a path (None) stands, the
        others follow theirs. ``halt``: every robot stands, a recovery under way too. ``poses``
        holds every robot of ``paths``; ``grid`` shows the obstacles its turns must mind."""
        commands = {}
        for name, path in paths.items():
            if not halt and self.recovery.active(name, now):
                commands[name] = self.recovery.command(name)
                self.follower.end_turn(name)
            elif halt or path is None:
                commands[name] = (0.0, 0.0)
                self.follower.end_turn(name)
            else:
                commands[name] = self.follower.command(name, grid, np.asarray(poses[name], float), path, now)
        return commands

    def counters(self) -> dict[str, int]:
        """How often each event happened so far: ``boxed_in`` (see :class:`Recovery`),
        ``long_turns``, ``turn_backoffs``, ``blocked_turns`` (see :class:`Follower`)."""
        f, r = self.follower, self.recovery
        return {"boxed_in": r.boxed_in, "long_turns": f.long_turns,
                "turn_backoffs": f.turn_backoffs, "blocked_turns": f.blocked_turns}
