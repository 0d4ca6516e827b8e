"""The central exploration agent: frontiers, costs, coordinated assignment, paths, progress."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from enum import Enum

import numpy as np
from scipy import ndimage

from mrslam_core.exploration.assignment import assign_targets
from mrslam_core.exploration.config import ExplorationConfig
from mrslam_core.exploration.cost import travel_cost
from mrslam_core.exploration.frontiers import frontier_cells, frontier_groups, frontier_targets, standing_cells
from mrslam_core.exploration.grid import OccupancyGrid
from mrslam_core.exploration.planning import astar, inflate, pure_pursuit
from mrslam_core.geometry.se2 import wrap_angle


#: ``open_side_turns``: turns on the spot larger than this [rad] may go the long way round, when the
#: short way sweeps the heading past an occupied cell nearer than ``OPEN_SIDE_NEAR`` [m] and the long
#: way keeps ``OPEN_SIDE_GAIN`` [m] further from any
OPEN_SIDE_TURN, OPEN_SIDE_NEAR, OPEN_SIDE_GAIN = np.radians(120.0), 0.6, 0.2

#: ``turn_clearance``: a robot backs away at most ``BACK_MAX`` [m] before a turn on the spot, in
#: ``BACK_STEP`` [m] steps, and only where the fan of ±``BACK_FAN`` [rad] behind it is free of
#: occupied cells to ``BACK_REAR`` [m] (its body's rear from its axle, plus 0.1 m) beyond the
#: distance backed
BACK_MAX, BACK_STEP, BACK_FAN, BACK_REAR = 0.4, 0.1, np.radians(35.0), 0.365

#: ``turn_stall_time``: a turn on the spot counts as blocked when the heading moved less than this
#: [rad] in that time
TURN_STALL_ANGLE = np.radians(5.0)

#: candidate targets within this of a robot's current target count as that target (``keep_goal``);
#: the candidates along a frontier are 1 m apart [m]
KEEP_RADIUS = 1.0


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


def disc_cells(grid: OccupancyGrid, centres: list[np.ndarray], radius: float) -> np.ndarray:
    """(H, W) bool: the cells within ``radius`` [m] of any of ``centres``, each (x, y) [m] map
    frame (bumper hits, other robots)."""
    out = np.zeros(grid.shape, bool)
    for xy in centres:
        out |= surroundings(grid, xy, radius - 2 * grid.res)
    return out


def ahead_within(pose: np.ndarray, others: list[np.ndarray], distance: float, direction: float = 1.0) -> bool:
    """Whether any of ``others`` (x, y, ...) [m] lies within ``distance`` [m] of ``pose`` (x, y, θ)
    and on the side it drives to: in front (``direction`` > 0) or behind (< 0) of its axle."""
    heading = np.array([np.cos(pose[2]), np.sin(pose[2])])
    for other in others:
        d = np.asarray(other, float)[:2] - pose[:2]
        if np.hypot(*d) < distance and direction * float(d @ heading) > 0:
            return True
    return False


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


def sweep_clearance(grid: OccupancyGrid, blocked: np.ndarray, pose: np.ndarray, turn: float, reach: float,
                    step: float = np.radians(10.0)) -> float:
    """Nearest cell of ``blocked`` (H, W) [m] (``reach`` when none) seen along the headings a turn
    on the spot from ``pose`` (x, y, θ) by ``turn`` [rad] sweeps: rays from the robot's centre
    every ``step`` [rad] of the sweep (the current heading, where either way round starts, left
    out), sampled every half cell up to ``reach`` [m]."""
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


def planning_layers(grid: OccupancyGrid, poses: list[np.ndarray], cfg: ExplorationConfig,
                    bumps: list[np.ndarray] = ()) -> tuple[np.ndarray, np.ndarray]:
    """What paths may cross: (passable (H, W) bool for A*, occupancy (H, W) for the travel cost).

    Obstacles (occupied cells and ``bumps``, see :func:`disc_cells`) are inflated by
    ``robot_radius``. Without ``unknown_passable`` only cells observed free are passable and
    unobserved ones cost like obstacles, except within the robot's radius (+ 2 cells) of a robot's
    pose (x, y, θ): the ground under and just around a robot is never in view, and it must be able
    to leave it.
    """
    blocked = grid.occupied() | disc_cells(grid, list(bumps), cfg.bumper_range / 2)
    prob = np.where(blocked, 1.0, grid.probability())
    passable = ~inflate(blocked, cfg.robot_radius / grid.res)
    if not cfg.unknown_passable:
        around = np.zeros(grid.shape, bool)
        for pose in poses:
            around |= surroundings(grid, np.asarray(pose)[:2], cfg.robot_radius)
        passable &= grid.free() | (around & ~blocked)
        prob = np.where(grid.observed | around, prob, 1.0)
    return passable, prob


@dataclass
class Explorer:
    """Coordinated frontier exploration for robots ``robots`` (002 section V).

    Call :meth:`step` with the current grid, every robot's pose (map frame) and the time; it
    (re)assigns targets when due and returns each robot's (v, ω) command. The grid may grow
    between calls (its cell (0, 0) moves): everything kept from one call to the next (targets,
    paths, blacklist, bumper hits, checkpoints) is in metres, map frame, never grid cells.
    """

    config: ExplorationConfig
    robots: list[str]
    starts: dict[str, np.ndarray] = field(default_factory=dict)
    goals: dict[str, Goal | None] = field(default_factory=dict)
    blacklist: list[np.ndarray] = field(default_factory=list)
    strikes: list[list[float]] = field(default_factory=list)  # per entry: [failures, blocked until s]
    state: State = State.EXPLORING
    last_plan_s: float = -np.inf
    plans: int = 0
    checkpoints: dict[str, tuple[np.ndarray, float]] = field(default_factory=dict)
    recovering_until: dict[str, float] = field(default_factory=dict)
    #: per robot, the direction of its last recovery (−1 backward, +1 forward) and its (x, y) [m]
    #: when the recovery began
    recovery: dict[str, tuple[float, np.ndarray]] = field(default_factory=dict)
    known_at_plan: int = 0
    #: bumper hits: (x, y) [m] map frame, obstacles for planning until ``bump_until`` [s]
    bumps: list[np.ndarray] = field(default_factory=list)
    bump_until: list[float] = field(default_factory=list)
    stalls: int = 0
    #: follower commands held at v = 0 because another robot stood in the way (``keep_clear``)
    held: int = 0
    #: goals a robot could not plan to because it could reach none of the targets from its spot
    #: (see :meth:`_set_goal`): it recovered instead of blacklisting the target
    boxed_in: int = 0
    #: per robot, the time of its first pose [s] (``start_delay``)
    first_seen: dict[str, float] = field(default_factory=dict)
    #: per robot, recent (time [s], x, y, commanded v [m/s]) for the stall check
    motion: dict[str, deque] = field(default_factory=dict)
    #: per robot turning on the spot the long way round (``open_side_turns``): its turn direction
    spin: dict[str, float] = field(default_factory=dict)
    #: turns on the spot sent the long way round (``open_side_turns``)
    long_turns: int = 0
    #: per robot backing away before a turn on the spot (``turn_clearance``): where it began
    #: (x, y) [m], the distance to back [m] and the time it gives up [s]
    backing: dict[str, tuple[np.ndarray, float, float]] = field(default_factory=dict)
    #: per robot whose last command was a turn on the spot (checked for ``turn_clearance`` once,
    #: as it begins): since when [s], its heading then [rad], and whether it was reversed already
    turning: dict[str, tuple[float, float, bool]] = field(default_factory=dict)
    #: turns on the spot that did not turn and were sent the other way round (``turn_stall_time``)
    blocked_turns: int = 0
    #: turns on the spot preceded by backing away from an occupied cell (``turn_clearance``)
    turn_backoffs: int = 0
    #: the candidate targets of the last plan, one per frontier stretch (T, 2) [m] map frame
    frontiers: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))

    def _replan(self, grid: OccupancyGrid, poses: dict[str, np.ndarray], now: float) -> None:
        cfg = self.config
        free, known = grid.free(), grid.observed
        frontier = frontier_cells(free, known)
        self.plans += 1
        self.last_plan_s = now
        self.known_at_plan = int(grid.observed.sum())
        passable, prob = planning_layers(grid, [poses[n] for n in self.robots], cfg, self.bumps)
        if cfg.target_reach <= 0:
            frontier &= passable  # a frontier the robot cannot stand on (hugging a wall) is not a goal
        waiting = False  # a frontier blocked only for now will be tried again: not complete yet
        blocked, for_now = [], []  # blacklist entries in force: (x, y) [m], and whether only for a while
        if self.blacklist:
            centres = grid.centre_of(np.argwhere(frontier))
            bad = np.zeros(len(centres), bool)
            for b, (fails, until) in zip(self.blacklist, self.strikes):
                if fails >= cfg.max_strikes or now < until:
                    blocked.append(b)
                    for_now.append(fails < cfg.max_strikes)
                    near = np.linalg.norm(centres - b, axis=1) < cfg.blacklist_radius
                    bad |= near
                    waiting |= fails < cfg.max_strikes and int(near.sum()) >= cfg.min_frontier_cells
            fc = np.argwhere(frontier)[bad]
            frontier[fc[:, 0], fc[:, 1]] = False
        groups = frontier_groups(frontier, cfg.min_frontier_cells)
        targets = frontier_targets(groups, max(1, int(round(1.0 / grid.res)))) if groups else np.zeros((0, 2), np.int64)
        if cfg.target_reach > 0 and len(targets):
            targets = standing_cells(targets, passable, cfg.target_reach / grid.res)
            if blocked and len(targets):  # a standing cell may lie off its frontier's blacklisted cells
                near = np.linalg.norm(grid.centre_of(targets)[:, None] - np.array(blocked)[None], axis=2) < cfg.blacklist_radius
                waiting |= bool(near[:, np.array(for_now)].any())  # near: (T, B)
                targets = targets[~near.any(axis=1)]
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
        if cfg.avoid_others:  # the unseen ground around any robot: another one would drive into it
            near = np.broadcast_to(near.any(axis=0), near.shape)
        far_cost = np.where(near, np.inf, cost)
        bonus = None
        if cfg.keep_goal > 0:  # a robot's current target, or the candidate that replaces it as the frontier recedes
            bonus = np.zeros(cost.shape)
            for i, name in enumerate(self.robots):
                g = self.goals.get(name)
                if g is not None and self.state is State.EXPLORING:
                    d = np.linalg.norm(txy - g.target, axis=1)
                    if d.min() <= KEEP_RADIUS:
                        bonus[i, int(np.argmin(d))] = cfg.keep_goal
        chosen = assign_targets(txy, far_cost, cfg.beta, cfg.utility_range, cfg.coordinated, bonus, cfg.best_pair)
        for i in np.flatnonzero(chosen < 0):  # only near frontiers left: turn and look at them
            if np.isfinite(cost[i]).any():
                chosen[i] = int(np.argmin(cost[i]))
        for name, j in zip(self.robots, chosen):
            if j < 0:
                self.goals[name] = None
            else:
                self._set_goal(name, txy[j], grid, passable, poses, now, txy)

    def _turn_side(self, name: str, grid: OccupancyGrid, pose: np.ndarray, aim: np.ndarray, v: float, w: float) -> float:
        """The turn rate of a robot turning on the spot (v = 0) towards ``aim`` (x, y) [m]: the
        long way round when the short way sweeps its heading past an occupied cell (see
        ``open_side_turns``); a turn once sent the long way keeps its direction until it ends."""
        if v != 0.0 or w == 0.0:
            self.spin.pop(name, None)
            return w
        bearing = float(np.arctan2(aim[1] - pose[1], aim[0] - pose[0]) - pose[2])
        bearing = float((bearing + np.pi) % (2 * np.pi) - np.pi)
        rate = self.config.max_turn_rate
        if name not in self.spin:
            if abs(bearing) <= OPEN_SIDE_TURN:
                return w
            occupied = grid.occupied()
            short = sweep_clearance(grid, occupied, pose, bearing, 1.0)
            long = sweep_clearance(grid, occupied, pose, bearing - np.sign(bearing) * 2 * np.pi, 1.0)
            if short >= OPEN_SIDE_NEAR or long < short + OPEN_SIDE_GAIN:
                return w
            self.spin[name] = -float(np.sign(bearing))
            self.long_turns += 1
        direction = self.spin[name]
        left = bearing if np.sign(bearing) == direction else bearing + direction * 2 * np.pi
        return float(direction * min(rate, 2.0 * abs(left)))

    def _end_turn(self, name: str) -> None:
        """Forget ``name``'s turn on the spot: its direction, its backing away, that it began."""
        self.spin.pop(name, None)
        self.backing.pop(name, None)
        self.turning.pop(name, None)

    def _unblock_turn(self, name: str, pose: np.ndarray, now: float, w: float) -> float:
        """The turn rate [rad/s] of ``name``, turning on the spot at ``w``: the other way round
        (once per turn) when its heading moved less than ``TURN_STALL_ANGLE`` in the last
        ``turn_stall_time`` s. A robot beside a door jamb or a teammate swings its body's corners
        out to 0.33 m from its axle; against them it turns no further however long it is told
        to, and the other way round frees it."""
        since, heading, reversed_ = self.turning[name]
        stall = self.config.turn_stall_time
        if stall <= 0 or now - since < stall:
            return w
        if abs(float(wrap_angle(pose[2] - heading))) >= TURN_STALL_ANGLE or reversed_:
            self.turning[name] = (now, float(pose[2]), reversed_)
            return w
        self.turning[name] = (now, float(pose[2]), True)
        self.spin[name] = -float(np.sign(w))
        self.blocked_turns += 1
        return -w

    def _turn_sweep(self, name: str, pose: np.ndarray, aim: np.ndarray) -> float:
        """The turn [rad] a robot at ``pose`` turning on the spot towards ``aim`` (x, y) [m] is to
        make: the short way, or the long way once ``open_side_turns`` sent it round."""
        bearing = float(np.arctan2(aim[1] - pose[1], aim[0] - pose[0]) - pose[2])
        bearing = float((bearing + np.pi) % (2 * np.pi) - np.pi)
        direction = self.spin.get(name)
        if direction is not None and np.sign(bearing) != direction:
            bearing += direction * 2 * np.pi
        return bearing

    def _backoff(self, grid: OccupancyGrid, pose: np.ndarray, turn: float) -> float:
        """How far [m] a robot at ``pose`` (x, y, θ) should back straight away before turning on
        the spot by ``turn`` [rad] (see ``turn_clearance``): the least multiple of ``BACK_STEP``
        after which the headings swept keep ``turn_clearance`` from every occupied cell; failing
        that, the one that gains the most clearance (0.1 m at least); 0 where the turn is clear
        already or there is no room behind."""
        need = self.config.turn_clearance
        occupied = grid.occupied()
        here = sweep_clearance(grid, occupied, pose, turn, need)
        if here >= need:
            return 0.0
        rear = np.array([pose[0], pose[1], pose[2] + np.pi - BACK_FAN])
        room = sweep_clearance(grid, occupied, rear, 2 * BACK_FAN, BACK_MAX + BACK_REAR) - BACK_REAR
        heading = np.array([np.cos(pose[2]), np.sin(pose[2])])
        best, gained = 0.0, here + 0.1
        for d in np.arange(BACK_STEP, min(BACK_MAX, room) + 1e-9, BACK_STEP):
            backed = np.array([*(pose[:2] - d * heading), pose[2]])
            clear = sweep_clearance(grid, occupied, backed, turn, need)
            if clear >= need:
                return float(d)
            if clear >= gained:
                best, gained = float(d), clear
        return best

    def _set_goal(self, name, target, grid, passable, poses, now, targets) -> None:
        """Plan ``name``'s path to ``target`` (x, y) [m]. When A* finds none, the target is struck
        (blacklisted) only if the robot can reach another of ``targets`` (T, 2) [m]. A robot
        boxed in (by a teammate, by obstacles mapped round it) reaches none, and striking each
        target it is given would blacklist, one after another, the targets its team can reach;
        it recovers instead (backs off, or pulls forward after a recovery that did not move it)
        and asks again."""
        start = tuple(np.clip(grid.cell_of(poses[name][:2]), 0, np.array(grid.shape) - 1))
        goal = tuple(np.clip(grid.cell_of(target), 0, np.array(grid.shape) - 1))
        # a robot standing closer than its radius to an obstacle may leave through inflated
        # cells around it (never through occupied ones)
        cfg = self.config
        near = surroundings(grid, poses[name][:2], cfg.robot_radius)
        leave = near & ~grid.occupied() & ~disc_cells(grid, self.bumps, cfg.bumper_range / 2)
        others = [np.asarray(poses[o])[:2] for o in self.robots if o != name]
        cost = np.where(grid.observed, 1.0, cfg.unknown_cost) if cfg.unknown_cost > 1 else None
        path = None
        clearance = max(cfg.keep_clear, cfg.path_clearance)
        if clearance > 0 and others:
            # around the other robots where there is room; else the plain path, on which the
            # follower waits for a robot in the way (keep_clear, see step)
            crowd = disc_cells(grid, others, clearance)
            path = astar((passable & ~crowd) | (leave & ~disc_cells(grid, others, clearance / 2)), start, goal, cost)
        if path is None:
            path = astar(passable | leave, start, goal, cost)
        if path is None:
            self.goals[name] = None
            if reaches_any(passable | leave, start, grid.cell_of(np.asarray(targets, float).reshape(-1, 2))):
                self._strike(np.asarray(target, float), now)
            else:
                self.boxed_in += 1
                self._recover(name, poses, now)
            return
        path_xy = grid.centre_of(np.array(path))
        self.goals[name] = Goal(np.asarray(target, float), path_xy, now)

    def _robot_ahead(self, name: str, poses: dict[str, np.ndarray], direction: float) -> bool:
        """Whether another robot stands within ``keep_clear`` of ``name`` on the side it would
        drive to (``direction`` > 0 forward, < 0 backward)."""
        if self.config.keep_clear <= 0:
            return False
        others = [poses[o] for o in self.robots if o != name]
        return ahead_within(np.asarray(poses[name], float), others, self.config.keep_clear, direction)

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

    def _recover(self, name: str, poses: dict[str, np.ndarray], now: float) -> None:
        """Drive ``name`` straight for ``recovery_time``, away from where it is stuck."""
        self.recovering_until[name] = now + self.config.recovery_time
        self.recovery[name] = (self._recovery_direction(name, poses), np.asarray(poses[name], float)[:2].copy())

    def _recovery_direction(self, name: str, poses: dict[str, np.ndarray]) -> float:
        """Back off (−1), unless the last recovery did not move the robot (< 5 cm): then the other
        way. A robot whose rear corner touches a wall cannot back off along it (the wheels do not
        slip), nor turn that corner into the wall; pulling forward frees it."""
        last = self.recovery.get(name)
        if last is None:
            return -1.0
        direction, start = last
        if np.linalg.norm(np.asarray(poses[name])[:2] - start) < 0.05:
            return -direction
        return -1.0

    def _stalled(self, name: str, poses: dict[str, np.ndarray], now: float) -> bool:
        """Whether ``name`` was commanded forward for ``stall_time`` and did not follow (see
        :class:`ExplorationConfig`); if so, a bumper hit is recorded ahead of it."""
        cfg = self.config
        track = self.motion.get(name)
        if cfg.stall_time <= 0 or not track or now - track[0][0] < cfg.stall_time:
            return False
        t = np.array([e[0] for e in track] + [now])
        v = np.array([e[3] for e in track])
        commanded = float(np.sum(np.maximum(v, 0.0) * np.diff(t)))
        pose = np.asarray(poses[name], float)
        moved = float(np.hypot(*(pose[:2] - np.array(track[0][1:3]))))
        if commanded < 0.1 * (now - track[0][0]) or moved >= 0.25 * commanded:
            return False
        self.stalls += 1
        # a robot pressing against another robot has not found a wall
        if any(np.hypot(*(np.asarray(poses[o])[:2] - pose[:2])) < 2 * cfg.bumper_range + 0.2
               for o in poses if o != name):
            track.clear()
            return True
        self.bumps.append(pose[:2] + cfg.bumper_range * np.array([np.cos(pose[2]), np.sin(pose[2])]))
        self.bump_until.append(now + cfg.blacklist_period)
        track.clear()
        return True

    def step(self, grid: OccupancyGrid, poses: dict[str, np.ndarray], now: float) -> dict[str, tuple[float, float]]:
        """Commands (v [m/s], ω [rad/s]) per robot at time ``now`` [s]."""
        cfg = self.config
        for name in self.robots:
            self.starts.setdefault(name, np.asarray(poses[name], float).copy())
            self.first_seen.setdefault(name, now)
        live = [i for i, until in enumerate(self.bump_until) if now < until]
        self.bumps, self.bump_until = [self.bumps[i] for i in live], [self.bump_until[i] for i in live]
        due = now - self.last_plan_s >= cfg.replan_period
        known = int(grid.observed.sum())
        if known - self.known_at_plan > cfg.replan_new_area / grid.res**2 and now - self.last_plan_s >= 1.0:
            due = True  # the map changed: frontiers may have moved
        for name in self.robots:
            g = self.goals.get(name)
            if g is None or self._robot_ahead(name, poses, 1.0):
                due |= now - self.last_plan_s >= 1.0  # idle or held robots ask again, at most once a second
            if g is None:
                continue
            d = float(np.linalg.norm(poses[name][:2] - g.target))
            where, since = self.checkpoints.setdefault(name, (poses[name][:2].copy(), now))
            if d < cfg.goal_tolerance:
                due = True
                self.goals[name] = None
            elif np.linalg.norm(poses[name][:2] - where) > 0.3:
                self.checkpoints[name] = (poses[name][:2].copy(), now)
            elif now - since > cfg.progress_timeout or self._stalled(name, poses, now):
                # no headway for a while (blocked, or oscillating): never chase this goal again
                self._strike(g.target, now)
                self.goals[name] = None
                self.checkpoints[name] = (poses[name][:2].copy(), now)
                self._recover(name, poses, now)  # back off before the next goal
                due = True
        if due and self.state is not State.COMPLETE:
            grid_ok = grid.observed.any()
            if grid_ok:
                self._replan(grid, poses, now)
        commands = {}
        for name in self.robots:
            g = self.goals.get(name)
            if now < self.recovering_until.get(name, -np.inf) and self.state is not State.COMPLETE:
                commands[name] = (self.recovery.get(name, (-1.0, None))[0] * cfg.recovery_speed, 0.0)
                self._end_turn(name)
                continue
            if g is None or self.state is State.COMPLETE or now - self.first_seen[name] < cfg.start_delay:
                commands[name] = (0.0, 0.0)
                self._end_turn(name)
                continue
            pose = np.asarray(poses[name], float)
            backing = self.backing.get(name)
            if backing is not None:
                start, distance, until = backing
                if np.linalg.norm(pose[:2] - start) < distance and now < until:
                    commands[name] = (-cfg.recovery_speed, 0.0)
                    continue
                del self.backing[name]  # the turn it backed away for begins, unchecked
            v, w, idx = pure_pursuit(pose, g.path, cfg.lookahead, cfg.max_speed, cfg.max_turn_rate, cfg.keep_arc)
            if cfg.open_side_turns or name in self.spin:
                w = self._turn_side(name, grid, pose, g.path[idx], v, w)
            if v != 0.0 or w == 0.0:
                self.turning.pop(name, None)
            elif name not in self.turning:
                self.turning[name] = (now, float(pose[2]), False)
                distance = self._backoff(grid, pose, self._turn_sweep(name, pose, g.path[idx])) if cfg.turn_clearance > 0 else 0.0
                if distance > 0:
                    self.backing[name] = (pose[:2].copy(), distance, now + distance / cfg.recovery_speed + 2.0)
                    self.turn_backoffs += 1
                    v, w = -cfg.recovery_speed, 0.0
            else:
                w = self._unblock_turn(name, pose, now, w)
            commands[name] = (v, w)
        for name, (v, w) in commands.items():
            if v != 0.0 and self._robot_ahead(name, poses, np.sign(v)):
                commands[name] = (0.0, w)  # never drive into another robot's clearance
                self.held += 1
        for name, (v, _) in commands.items():
            track = self.motion.setdefault(name, deque())
            track.append((now, *np.asarray(poses[name], float)[:2], v))
            while len(track) > 2 and track[1][0] <= now - cfg.stall_time:
                track.popleft()
        if self.state is State.RETURNING and all(
            np.linalg.norm(poses[n][:2] - self.starts[n][:2]) < cfg.goal_tolerance for n in self.robots
        ):
            self.state = State.COMPLETE
        return commands
