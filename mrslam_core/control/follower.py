"""Path following with rules for turns on the spot: pure pursuit, turning round the open side of
a wall, backing away before a turn, and reversing a turn that does not turn."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mrslam_core.control.config import ControlConfig
from mrslam_core.control.pursuit import pure_pursuit
from mrslam_core.geometry.se2 import wrap_angle

if TYPE_CHECKING:
    from mrslam_core.exploration.grid import OccupancyGrid


def sweep_clearance(grid: OccupancyGrid, blocked: np.ndarray, pose: np.ndarray, turn: float, reach: float,
                    step: float = np.radians(10.0)) -> float:
    """Nearest cell of ``blocked`` (H, W) bool [m] (``reach`` when none) seen along the headings a
    turn on the spot from ``pose`` (x, y, θ) [m, rad], map frame, by ``turn`` [rad] sweeps: rays
    from the robot's centre every ``step`` [rad] of the sweep (the current heading, where either
    way round starts, left out), sampled every half cell up to ``reach`` [m]."""
    n = int(np.ceil(abs(turn) / step)) + 1
    heading = pose[2] + np.linspace(0.0, turn, n)[1:]
    r = np.arange(grid.res / 2, reach, grid.res / 2)
    xy = pose[:2] + r[None, :, None] * np.stack([np.cos(heading), np.sin(heading)], -1)[:, None, :]
    cells = grid.cell_of(xy)
    inside = grid.inside(cells)
    hit = np.zeros(inside.shape, bool)
    hit[inside] = blocked[cells[inside][:, 0], cells[inside][:, 1]]
    if not hit.any():
        return float(reach)
    return float(r[hit.argmax(axis=1)[hit.any(axis=1)]].min())


def _bearing(pose: np.ndarray, aim: np.ndarray) -> float:
    """Bearing [rad] in [-π, π) of ``aim`` (x, y) [m] from ``pose`` (x, y, θ) [m, rad]."""
    bearing = float(np.arctan2(aim[1] - pose[1], aim[0] - pose[0]) - pose[2])
    return float((bearing + np.pi) % (2 * np.pi) - np.pi)


class Follower:
    """Each robot's (v, ω) along its path (map frame), with the turn-on-the-spot rules of
    ``config`` (:class:`ControlConfig`: ``open_side_turns``, ``turn_clearance``,
    ``turn_stall_time``). Keeps, per robot, the state of the turn on the spot it is making."""

    def __init__(self, config: ControlConfig):
        self.config = config
        #: per robot turning on the spot the long way round: its turn direction (±1)
        self.spin: dict[str, float] = {}
        #: per robot backing away before a turn on the spot: where it began (x, y) [m], the
        #: distance to back [m] and the time it gives up [s]
        self.backing: dict[str, tuple[np.ndarray, float, float]] = {}
        #: per robot whose last command was a turn on the spot (checked for ``turn_clearance``
        #: once, as it begins): since when [s], its heading then [rad], and whether it was
        #: reversed already
        self.turning: dict[str, tuple[float, float, bool]] = {}
        #: turns on the spot sent the long way round (``open_side_turns``)
        self.long_turns = 0
        #: turns on the spot preceded by backing away from an occupied cell (``turn_clearance``)
        self.turn_backoffs = 0
        #: turns on the spot that did not turn and were sent the other way round (``turn_stall_time``)
        self.blocked_turns = 0

    def command(self, name: str, grid: OccupancyGrid, pose: np.ndarray, path: np.ndarray,
                now: float) -> tuple[float, float]:
        """(v [m/s], ω [rad/s]) for robot ``name`` at ``pose`` (x, y, θ) [m, rad] to follow
        ``path`` (N, 2) [m] at time ``now`` [s]; ``grid``'s occupied cells decide its turns on
        the spot."""
        cfg, platform = self.config, self.config.platform
        backing = self.backing.get(name)
        if backing is not None:
            start, distance, until = backing
            if np.linalg.norm(pose[:2] - start) < distance and now < until:
                return -cfg.recovery_speed, 0.0
            del self.backing[name]  # the turn it backed away for begins, unchecked
        v, w, idx = pure_pursuit(pose, path, cfg.lookahead, platform.max_speed, platform.max_turn_rate, cfg.keep_arc)
        if cfg.open_side_turns or name in self.spin:
            w = self._turn_side(name, grid, pose, path[idx], v, w)
        if v != 0.0 or w == 0.0:
            self.turning.pop(name, None)
        elif name not in self.turning:
            self.turning[name] = (now, float(pose[2]), False)
            if cfg.turn_clearance > 0:
                distance = self.backoff(grid, pose, self._turn_sweep(name, pose, path[idx]))
                if distance > 0:
                    # given up when it has not got there in the time it takes, plus 2 s
                    self.backing[name] = (pose[:2].copy(), distance, now + distance / cfg.recovery_speed + 2.0)
                    self.turn_backoffs += 1
                    return -cfg.recovery_speed, 0.0
        else:
            w = self._unblock_turn(name, pose, now, w)
        return v, w

    def end_turn(self, name: str) -> None:
        """Forget ``name``'s turn on the spot: its direction, its backing away, that it began."""
        self.spin.pop(name, None)
        self.backing.pop(name, None)
        self.turning.pop(name, None)

    def _turn_side(self, name: str, grid: OccupancyGrid, pose: np.ndarray, aim: np.ndarray, v: float,
                   w: float) -> float:
        """The turn rate [rad/s] of a robot at ``pose`` turning on the spot (v = 0) at ``w``
        towards ``aim`` (x, y) [m]: the long way round when the short way sweeps its heading past
        an occupied cell (``open_side_turns``); a turn once sent the long way keeps its direction
        until it ends."""
        if v != 0.0 or w == 0.0:
            self.spin.pop(name, None)
            return w
        cfg = self.config
        bearing = _bearing(pose, aim)
        rate = cfg.platform.max_turn_rate
        if name not in self.spin:
            if abs(bearing) <= cfg.open_side_turn:
                return w
            occupied = grid.occupied()
            # occupied cells within 1 m, either way round
            short = sweep_clearance(grid, occupied, pose, bearing, 1.0)
            long = sweep_clearance(grid, occupied, pose, bearing - np.sign(bearing) * 2 * np.pi, 1.0)
            if short >= cfg.open_side_near or long < short + cfg.open_side_gain:
                return w
            self.spin[name] = -float(np.sign(bearing))
            self.long_turns += 1
        direction = self.spin[name]
        left = bearing if np.sign(bearing) == direction else bearing + direction * 2 * np.pi
        return float(direction * min(rate, 2.0 * abs(left)))

    def _unblock_turn(self, name: str, pose: np.ndarray, now: float, w: float) -> float:
        """The turn rate [rad/s] of ``name`` at ``pose``, turning on the spot at ``w``: the other
        way round (once per turn) when its heading moved less than ``turn_stall_angle`` in the
        last ``turn_stall_time`` s. A robot beside a door jamb or a teammate swings its body's
        corners out; against them it turns no further however long it is told to, and the
        other way round frees it."""
        since, heading, reversed_ = self.turning[name]
        cfg = self.config
        if cfg.turn_stall_time <= 0 or now - since < cfg.turn_stall_time:
            return w
        if abs(float(wrap_angle(pose[2] - heading))) >= cfg.turn_stall_angle or reversed_:
            self.turning[name] = (now, float(pose[2]), reversed_)
            return w
        self.turning[name] = (now, float(pose[2]), True)
        self.spin[name] = -float(np.sign(w))
        self.blocked_turns += 1
        return -w

    def _turn_sweep(self, name: str, pose: np.ndarray, aim: np.ndarray) -> float:
        """The turn [rad] a robot at ``pose`` turning on the spot towards ``aim`` (x, y) [m] is to
        make: the short way, or the long way once ``open_side_turns`` sent it round."""
        bearing = _bearing(pose, aim)
        direction = self.spin.get(name)
        if direction is not None and np.sign(bearing) != direction:
            bearing += direction * 2 * np.pi
        return bearing

    def backoff(self, grid: OccupancyGrid, pose: np.ndarray, turn: float) -> float:
        """How far [m] a robot at ``pose`` (x, y, θ) [m, rad] should back straight away before
        turning on the spot by ``turn`` [rad] (``turn_clearance``): the least multiple of
        ``back_step`` after which the headings swept keep ``turn_clearance`` from every
        occupied cell; failing that, the one that gains the most clearance (0.1 m at least); 0
        where the turn is clear already or there is no room behind."""
        cfg = self.config
        need = cfg.turn_clearance
        occupied = grid.occupied()
        here = sweep_clearance(grid, occupied, pose, turn, need)
        if here >= need:
            return 0.0
        behind = cfg.platform.rear + cfg.back_margin  # from the axle: the body, and room to spare
        rear = np.array([pose[0], pose[1], pose[2] + np.pi - cfg.back_fan])
        room = sweep_clearance(grid, occupied, rear, 2 * cfg.back_fan, cfg.back_max + behind) - behind
        heading = np.array([np.cos(pose[2]), np.sin(pose[2])])
        best, gained = 0.0, here + 0.1
        for d in np.arange(cfg.back_step, min(cfg.back_max, room) + 1e-9, cfg.back_step):
            backed = np.array([*(pose[:2] - d * heading), pose[2]])
            clear = sweep_clearance(grid, occupied, backed, turn, need)
            if clear >= need:
                return float(d)
            if clear >= gained:
                best, gained = float(d), clear
        return best
