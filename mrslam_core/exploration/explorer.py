"""The central exploration agent: frontiers, costs, coordinated assignment, paths, progress; the
drive commands along the paths come from a :class:`~mrslam_core.control.controller.Controller`."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

import numpy as np
from scipy import ndimage

from mrslam_core.control.controller import Controller
from mrslam_core.exploration.assignment import assign_targets
from mrslam_core.exploration.config import ExplorationConfig
from mrslam_core.exploration.cost import travel_cost
from mrslam_core.exploration.frontiers import frontier_cells, frontier_groups, frontier_targets
from mrslam_core.exploration.grid import OccupancyGrid
from mrslam_core.exploration.planning import astar, inflate


class State(Enum):
    EXPLORING = "exploring"
    RETURNING = "returning"
    COMPLETE = "complete"


@dataclass
class Goal:
    """A robot's current goal: target (x, y) [m] and path (N, 2) [m]."""

    target: np.ndarray
    path: np.ndarray
    assigned_s: float


def surroundings(grid: OccupancyGrid, xy: np.ndarray, robot_radius: float) -> np.ndarray:
    """(H, W) bool: the cells within ``robot_radius`` [m] + 2 cells of the robot at ``xy`` (2,) [m]."""
    r0, c0 = np.clip(grid.cell_of(xy), 0, np.array(grid.shape) - 1)
    rr, cc = np.ogrid[: grid.shape[0], : grid.shape[1]]
    return (rr - r0) ** 2 + (cc - c0) ** 2 <= (robot_radius / grid.res + 2) ** 2


def reaches_any(passable: np.ndarray, start: tuple[int, int], cells: np.ndarray) -> bool:
    """Whether any of ``cells`` (T, 2) (row, col) lies in the 8-connected region of ``passable``
    (H, W) bool that holds ``start`` (row, col); cells off the grid never do."""
    labels, _ = ndimage.label(passable, structure=np.ones((3, 3), bool))
    own = labels[start]
    if own == 0 or not len(cells):
        return False
    inside = np.all((cells >= 0) & (cells < np.array(passable.shape)), axis=1)
    rc = cells[inside]
    return bool(np.any(labels[rc[:, 0], rc[:, 1]] == own))


def planning_layers(grid: OccupancyGrid, cfg: ExplorationConfig) -> tuple[np.ndarray, np.ndarray]:
    """What paths may cross: (passable (H, W) bool for A*, occupancy (H, W) for the travel cost).

    Occupied cells are inflated by ``robot_radius``; cells never observed are passable.
    """
    blocked = grid.occupied()
    prob = np.where(blocked, 1.0, grid.probability())
    passable = ~inflate(blocked, cfg.robot_radius / grid.res)
    return passable, prob


@dataclass
class Explorer:
    """Coordinated frontier exploration for robots ``robots`` (002 section V).

    Call :meth:`step` with the current grid, every robot's pose (map frame) and the time; it
    (re)assigns targets when due and returns each robot's (v, ω) command from ``controller``
    (which counts the recoveries and turns). The grid may grow between calls (its cell
    (0, 0) moves): everything kept from one call to the next (targets, paths, blacklist,
    checkpoints) is in metres, map frame, never grid cells.

    Raises:
        ValueError: ``config.robot_radius`` is smaller than the controller's platform's
            ``corner_radius``: paths inflated by less let the body's corners hit what the robot
            turns beside.
    """

    config: ExplorationConfig
    robots: list[str]
    controller: Controller = field(default_factory=Controller)
    starts: dict[str, np.ndarray] = field(default_factory=dict)
    goals: dict[str, Goal | None] = field(default_factory=dict)
    blacklist: list[np.ndarray] = field(default_factory=list)
    strikes: list[list[float]] = field(default_factory=list)  # per entry: [failures, blocked until s]
    state: State = State.EXPLORING
    last_plan_s: float = -np.inf
    plans: int = 0
    checkpoints: dict[str, tuple[np.ndarray, float]] = field(default_factory=dict)
    known_at_plan: int = 0
    #: grid cells the bumpers marked, and goals failed because a robot's bumper was pressed
    #: ahead of it (:meth:`bumped`)
    bumped_cells: int = 0
    bumped_goals: int = 0
    #: per robot, the time of its first pose [s] (``start_delay``)
    first_seen: dict[str, float] = field(default_factory=dict)
    #: the candidate targets of the last plan, one per frontier stretch (T, 2) [m] map frame
    frontiers: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))

    def __post_init__(self) -> None:
        body = self.controller.config.platform.corner_radius
        if self.config.robot_radius < body:
            raise ValueError(f"exploration robot_radius {self.config.robot_radius} m is smaller than the platform's "
                             f"corner_radius {body:.3f} m (its footprint's farthest corner from base_link)")

    def _replan(self, grid: OccupancyGrid, poses: dict[str, np.ndarray], now: float) -> None:
        cfg = self.config
        free, known = grid.free(), grid.observed
        frontier = frontier_cells(free, known)
        self.plans += 1
        self.last_plan_s = now
        self.known_at_plan = int(grid.observed.sum())
        passable, prob = planning_layers(grid, cfg)
        frontier &= passable  # a frontier the robot cannot stand on (hugging a wall) is not a goal
        waiting = False  # a frontier blocked only for now will be tried again: not complete yet
        if self.blacklist:
            centres = grid.centre_of(np.argwhere(frontier))
            bad = np.zeros(len(centres), bool)
            for b, (fails, until) in zip(self.blacklist, self.strikes):
                if fails >= cfg.max_strikes or now < until:
                    near = np.linalg.norm(centres - b, axis=1) < cfg.blacklist_radius
                    bad |= near
                    waiting |= fails < cfg.max_strikes and int(near.sum()) >= cfg.min_frontier_cells
            fc = np.argwhere(frontier)[bad]
            frontier[fc[:, 0], fc[:, 1]] = False
        groups = frontier_groups(frontier, cfg.min_frontier_cells)
        targets = frontier_targets(groups, max(1, int(round(1.0 / grid.res)))) if groups else np.zeros((0, 2), np.int64)
        self.frontiers = grid.centre_of(targets) if len(targets) else np.zeros((0, 2))
        if not len(targets) and free.any() and not waiting:
            if self.state is State.EXPLORING:
                self.state = State.RETURNING if cfg.return_to_start else State.COMPLETE
            if self.state is State.RETURNING:
                for name in self.robots:
                    self._set_goal(name, self.starts[name][:2], grid, passable, poses, now, self.starts[name][None, :2])
            return
        if not len(targets):
            return
        cells = np.array([grid.cell_of(poses[n][:2]) for n in self.robots])
        cells = np.clip(cells, 0, np.array(grid.shape) - 1)
        cost = travel_cost(prob, cells, cfg.occ_max, grid.res)[:, targets[:, 0], targets[:, 1]]
        txy = grid.centre_of(targets)
        robot_xy = np.array([poses[n][:2] for n in self.robots])
        near = np.linalg.norm(txy[None] - robot_xy[:, None], axis=2) < cfg.min_target_distance  # (R, T)
        far_cost = np.where(near, np.inf, cost)
        chosen = assign_targets(txy, far_cost, cfg.beta, cfg.utility_range, cfg.coordinated)
        for i in np.flatnonzero(chosen < 0):  # only near frontiers left: turn and look at them
            if np.isfinite(cost[i]).any():
                chosen[i] = int(np.argmin(cost[i]))
        for name, j in zip(self.robots, chosen):
            if j < 0:
                self.goals[name] = None
            else:
                self._set_goal(name, txy[j], grid, passable, poses, now, txy)

    def _set_goal(self, name, target, grid, passable, poses, now, targets) -> None:
        """Plan ``name``'s path to ``target`` (x, y) [m]. When A* finds none, the target is struck
        (blacklisted) only if the robot can reach another of ``targets`` (T, 2) [m]. A robot
        boxed in (by a teammate, by obstacles mapped round it) reaches none, and striking each
        target it is given would blacklist, one after another, the targets its team can reach;
        it recovers instead (backs off, or pulls forward after a recovery that did not move it)
        and asks again."""
        start = tuple(np.clip(grid.cell_of(poses[name][:2]), 0, np.array(grid.shape) - 1))
        goal = tuple(np.clip(grid.cell_of(target), 0, np.array(grid.shape) - 1))
        # a robot standing closer than its radius (or its camera's near limit) to an obstacle may
        # leave through inflated cells around it, never through occupied ones nor the cells next
        # to them (its centre there would put its side, half a body width out, in the obstacle)
        cfg = self.config
        near = surroundings(grid, poses[name][:2], max(cfg.robot_radius, self._unseen))
        leave = near & ~inflate(grid.occupied(), 1.5)
        path = astar(passable | leave, start, goal)
        if path is None:
            self.goals[name] = None
            if reaches_any(passable | leave, start, grid.cell_of(np.asarray(targets, float).reshape(-1, 2))):
                self._strike(np.asarray(target, float), now)
            else:
                self.controller.recovery.start_boxed_in(name, poses[name], now)
            return
        path_xy = grid.centre_of(np.array(path))
        self.goals[name] = Goal(np.asarray(target, float), path_xy, now)

    @property
    def _unseen(self) -> float:
        """Radius [m] round a robot that its camera never sees: the platform's ``camera_near``."""
        return self.controller.config.platform.camera_near

    def bumped(self, grid: OccupancyGrid, name: str, points: np.ndarray, poses: dict[str, np.ndarray],
               now: float) -> bool:
        """``name``'s bumper is pressed at ``points`` (K, 2) (x, y) in its base_link [m] at ``now``
        [s], every robot at its pose of ``poses`` (x, y, θ) map frame. What it touched is an
        occupied cell of ``grid`` for good (``OccupancyGrid.touch``; a touch on a teammate marks
        nothing), counted in ``bumped_cells``. Pressed ahead of its axle (x > 0) while it drives
        to a goal, it pushes into what it touched: the goal fails at once, as after
        ``progress_timeout`` without headway, instead of after pushing for that long. Returns
        whether the goal failed (counted as ``bumped_goals``)."""
        points = np.asarray(points, float).reshape(-1, 2)
        pose = np.asarray(poses[name], float)
        teammates = [np.asarray(p)[:2] for r, p in poses.items() if r != name]
        self.bumped_cells += grid.touch(pose, points, teammates)
        goal = self.goals.get(name)
        if goal is None or not (points[:, 0] > 0).any() or self.controller.recovery.active(name, now):
            return False
        self._give_up(name, goal, pose, now)
        self.bumped_goals += 1
        return True

    def _give_up(self, name: str, goal: Goal, pose: np.ndarray, now: float) -> None:
        """``name`` made no headway to ``goal`` from ``pose`` (x, y, θ) [m, rad]: never chase it
        again (struck), and back off before the next goal."""
        self._strike(goal.target, now)
        self.goals[name] = None
        self.checkpoints[name] = (pose[:2].copy(), now)
        self.controller.recovery.start(name, pose, now)

    def _strike(self, target: np.ndarray, now: float) -> None:
        """A goal failed (no path, or no headway): block it for a while; after ``max_strikes``
        failures at the same place, for good (so exploration neither hangs nor stops early)."""
        cfg = self.config
        for b, strike in zip(self.blacklist, self.strikes):
            if np.linalg.norm(b - target) < cfg.blacklist_radius:
                if now >= strike[1]:  # robots failing together on one goal count once
                    strike[0] += 1
                    strike[1] = now + cfg.blacklist_period
                return
        self.blacklist.append(np.asarray(target, float))
        self.strikes.append([1.0, now + cfg.blacklist_period])

    def step(self, grid: OccupancyGrid, poses: dict[str, np.ndarray], now: float) -> dict[str, tuple[float, float]]:
        """Commands (v [m/s], ω [rad/s]) per robot at time ``now`` [s]."""
        cfg = self.config
        for name in self.robots:
            self.starts.setdefault(name, np.asarray(poses[name], float).copy())
            self.first_seen.setdefault(name, now)
        due = now - self.last_plan_s >= cfg.replan_period
        known = int(grid.observed.sum())
        if known - self.known_at_plan > cfg.replan_new_area / grid.res**2 and now - self.last_plan_s >= 1.0:
            due = True  # the map changed: frontiers may have moved
        for name in self.robots:
            g = self.goals.get(name)
            if g is None:
                due |= now - self.last_plan_s >= 1.0  # idle robots ask again, at most once a second
            if g is None:
                continue
            d = float(np.linalg.norm(poses[name][:2] - g.target))
            where, since = self.checkpoints.setdefault(name, (poses[name][:2].copy(), now))
            if d < cfg.goal_tolerance:
                due = True
                self.goals[name] = None
            elif np.linalg.norm(poses[name][:2] - where) > 0.3:
                self.checkpoints[name] = (poses[name][:2].copy(), now)
            elif now - since > cfg.progress_timeout:
                self._give_up(name, g, np.asarray(poses[name], float), now)  # blocked, or oscillating
                due = True
        if due and self.state is not State.COMPLETE:
            grid_ok = grid.observed.any()
            if grid_ok:
                self._replan(grid, poses, now)
        halt = self.state is State.COMPLETE
        paths = {}
        for name in self.robots:
            g = self.goals.get(name)
            waiting = g is None or halt or now - self.first_seen[name] < cfg.start_delay
            paths[name] = None if waiting else g.path
        commands = self.controller.step(grid, poses, paths, now, halt)
        if self.state is State.RETURNING and all(
            np.linalg.norm(poses[n][:2] - self.starts[n][:2]) < cfg.goal_tolerance for n in self.robots
        ):
            self.state = State.COMPLETE
        return commands
