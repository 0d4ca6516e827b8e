"""Exploration of a robot that is not in the team's map frame yet (an unknown start pose).

Until the central mapper joins it (map alignment or rendezvous), such a robot has poses only in
its own start frame, from its local filter. It explores alone there, on a grid of its own, with
its own :class:`~mrslam_core.exploration.explorer.Explorer`. Its scans and their poses are kept:
when it joins, they are moved by the join's transform (own frame → map frame) into the team's grid,
so the area it explored is not explored again, and the robot becomes one of the team's explorer.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mrslam_core.control.controller import Controller
from mrslam_core.exploration.config import ExplorationConfig, GridConfig
from mrslam_core.exploration.explorer import Explorer
from mrslam_core.exploration.grid import OccupancyGrid, Scan
from mrslam_core.geometry.se2 import compose


@dataclass
class OwnFrameExploration:
    """One robot exploring in its own start frame.

    Attributes:
        grid: the robot's own occupancy grid (its start frame).
        explorer: frontier exploration of that grid by the robot alone.
        scans: every scan inserted: (pose (3,) [m, rad] own frame, the scan, the teammates' map-frame
            positions (T, 2) [m] at that time), replayed into the team's grid by :meth:`hand_over`.
    """

    grid: OccupancyGrid
    explorer: Explorer
    scans: list[tuple[np.ndarray, Scan, np.ndarray]] = field(default_factory=list)

    @classmethod
    def create(cls, robot: str, exploration: ExplorationConfig, grid: GridConfig,
               controller: Controller) -> OwnFrameExploration:
        """``controller``: the team's (it keeps each robot's follower and recovery state by name)."""
        return cls(OccupancyGrid(grid), Explorer(exploration, [robot], controller))

    def insert(self, pose: np.ndarray, scan: Scan, teammates: np.ndarray) -> None:
        """A scan at ``pose`` (own frame); ``teammates`` (T, 2) map frame, kept for the hand-over
        (the own grid cannot place them)."""
        self.grid.insert(pose, scan)
        self.scans.append((np.asarray(pose, float).copy(), scan, np.asarray(teammates, float).reshape(-1, 2)))

    def hand_over(self, team_grid: OccupancyGrid, transform: np.ndarray) -> int:
        """Insert every kept scan into ``team_grid`` at its pose moved by ``transform`` (3,) (own
        frame → map frame, tx [m], ty [m], θ [rad]); returns the number of scans."""
        for pose, scan, teammates in self.scans:
            team_grid.insert(compose(transform, pose), scan, teammates if len(teammates) else None)
        return len(self.scans)
