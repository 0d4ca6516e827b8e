"""Configuration of mapping and exploration (the only place its defaults are written)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class GridConfig:
    """Log-odds occupancy grid.

    Attributes:
        resolution: cell side [m].
        block: the grid grows by whole blocks of this side [m] (a whole multiple of
            ``resolution``), its edges on multiples of it in the map frame: in whichever
            direction a scan leaves the grid, that edge moves out to the next multiple (see
            :class:`~mrslam_core.exploration.grid.OccupancyGrid`). Larger blocks re-allocate
            less often (a copy of the grid: 0.4 ms for 40 × 30 m), smaller ones leave less
            unknown margin that frontier search and travel costs sweep at every re-assignment:
            in the 2D office simulation the median re-assignment took 25 / 28 / 42 / 57 ms with
            1 / 2 / 4 / 8 m blocks (27 ms on the former fixed 22 × 14 m grid).
        hit, miss: log-odds added for a beam end (obstacle) / a cell a beam passed.
        clamp: log-odds are kept in [-clamp, clamp].
        free_below, occupied_above: probability thresholds of free and occupied cells.
        teammate_radius: a beam ending within this of another robot's position (base_link, map
            frame) ended on that robot's body: it proves the space up to it free and marks no
            obstacle. Robots see each other; mapped, a teammate that drove on leaves an obstacle
            where no one looks again, and inflated for planning it sealed a start room's door
            (docs/results.md). The simulated Pioneer's body reaches 0.33 m from
            base_link; 0: off [m].
    """

    resolution: float = 0.1
    block: float = 1.0
    hit: float = 0.85
    miss: float = -0.7
    clamp: float = 4.0
    free_below: float = 0.4
    occupied_above: float = 0.65
    teammate_radius: float = 0.45

    def __post_init__(self) -> None:
        if not self.resolution > 0:
            raise ValueError("resolution must be > 0")
        cells = self.block / self.resolution
        if not (round(cells) >= 1 and abs(cells - round(cells)) < 1e-6):
            raise ValueError(f"block {self.block} m must be a whole multiple (>= 1) of resolution {self.resolution} m")


@dataclass(frozen=True)
class ExplorationConfig:
    """Frontier exploration (002 section V after Burgard et al. 2005).

    Attributes:
        coordinated: discount the utility of targets near already assigned ones (eq. 8–9);
            False sends every robot to its own best frontier.
        best_pair: assign the best (robot, target) pair first (Burgard et al. 2005) instead of
            the robots in list order (002 eq. 8). Measured in docs/results.md: it
            frees robots that list order sent into each other, but over 14 closed-loop seeds it
            left more robots above 0.10 m (9 of 42 against 2 of 42).
        beta: weight of the travel cost V in argmax(U − β·V).
        utility_range: max_range of the discount P(d) = 1 − d/max_range [m].
        occ_max: cells with occupancy probability above this are not traversable.
        min_frontier_cells: smaller frontier groups are ignored.
        robot_radius: obstacles are inflated by this for planning [m].
        target_reach: a frontier cell a robot cannot stand on (within ``robot_radius`` of an
            obstacle: beside a wall, or amid the scattered far-range hits of a stereo camera at
            the end of a corridor) is targeted from the nearest passable cell within this
            distance; frontiers with none are skipped (0: only frontier cells the robot can
            stand on are targets) [m].
        min_target_distance: frontier targets closer than this to the robot are skipped (the
            unknown just behind a robot with a forward-looking sensor is not worth a goal) [m].
        avoid_others: frontier targets closer than ``min_target_distance`` to any robot of the
            team are skipped, not only those near the robot itself: the ground around a robot
            is never in view (its own camera looks ahead), so its frontier is not worth a goal,
            and a teammate sent there drives into it (robots starting 1 m apart were sent to
            each other's start spots and wedged against each other).
        keep_goal: at a re-assignment, a robot's current target (the candidate nearest it,
            within 1 m, as its frontier recedes) scores this much more for that robot, so that it
            turns to a new target only for a clearly better one (utility units, U = 1 per
            target; 0: every re-assignment starts afresh). Robots that swap targets at every
            re-assignment turn on the spot, the hardest motion for a camera to track.
        goal_tolerance: a goal counts as reached within this distance [m].
        replan_period: re-assign targets at least this often [s].
        replan_new_area: re-assign sooner (at most once a second) when this much new area has
            been mapped since the last assignment [m²].
        progress_timeout: a goal with no progress for this long is blacklisted [s].
        blacklist_radius: frontier cells within this of a blacklisted goal are skipped [m].
        blacklist_period: a failed goal is skipped for this long, then tried again [s].
        max_strikes: after this many failures at one place it is skipped for good.
        recovery_time, recovery_speed: a robot that made no headway backs up this long at this
            speed before its next goal (a wedged robot frees itself) [s, m/s].
        return_to_start: drive back to the start pose once exploration is complete.
        max_speed, max_turn_rate: path follower limits [m/s, rad/s].
        lookahead: pure-pursuit lookahead distance [m].
        unknown_passable: paths and travel costs may cross cells never observed (right for a
            sensor that sees every obstacle before the robot reaches it). False: only cells
            observed free (for stereo cameras, which cannot see a wall nearer than their near
            limit and would otherwise plan through it once they stand close to it).
        unknown_cost: with ``unknown_passable``, a path's step into a cell never observed costs
            this many times a step into an observed one (>= 1; 1: no difference): paths keep to
            space seen free where the detour is short, instead of cutting across the unseen
            ground beside the robot, where a stereo camera looking ahead has not seen the wall.
        stall_time: a robot commanded forward for this long (at 0.1 m/s or more on average) that
            covered less than a quarter of the commanded distance is blocked by something its
            sensor does not show (a wall nearer than a stereo camera's near limit, a door frame
            beside it): its goal fails and it backs off at once instead of pushing for
            ``progress_timeout``, and a disc of radius ``bumper_range / 2`` around the spot
            ``bumper_range`` ahead of it is an obstacle (inflated by ``robot_radius``) for
            planning during ``blacklist_period`` (0: off) [s].
        bumper_range: distance from the robot's centre to the front of its body [m].
        keep_arc: where the pure-pursuit arc is tighter than ``max_speed / max_turn_rate``,
            slow down to drive it instead of clipping the turn rate and swinging wide (see
            :func:`~mrslam_core.exploration.planning.pure_pursuit`; measured in docs/results.md:
            fewer collisions with door frames but less area explored at first; later, on in the
            team defaults: more explored and no robot lost over 9 fresh seeds).
        keep_clear: distance [m] between robot centres (base_link) that robots keep from each
            other: a robot's path keeps this far from the other robots' positions where there is
            room, and a robot does not drive forward (backward) while another robot's centre is
            within it in front of (behind) its axle; it turns on the spot, waits, or is given a
            path around. Two robots whose bodies swing out to ``r`` when turning need more than
            2·r between centres to turn freely (0: off).
        path_clearance: a robot's path keeps this far [m] from the other robots' positions
            where there is room (else the plain path is kept), without ``keep_clear``'s holding.
            The occupancy grid leaves teammates out (``GridConfig.teammate_radius``); without
            this, paths ran through them: two robots crossing at the start drove into each other
            and stood wedged for the rest of the run (docs/results.md). Measured
            there at 0.8 m over 14 fresh closed-loop seeds: no wedge and more explored (65
            against 56 %), but more robots above 0.10 m (9 of 42 against 4 of 42), so off.
            The larger of this and ``keep_clear`` is used; 0: off.
        open_side_turns: a turn on the spot of more than 120° goes the long way round when
            the short way sweeps the robot's heading past an occupied cell nearer than 0.6 m
            and the long way does not come as near (0.2 m further or more): a stereo camera
            facing a wall nearer than its near limit sees nothing, and a robot that turned blind
            beside a wall came out 5-7° off in the recorded demos traced. On in the team defaults:
            lower ATE, less explored (docs/results.md).
        turn_clearance: before a turn on the spot whose headings come nearer than this [m] to an
            occupied cell (rays from the robot's centre), the robot first backs straight away,
            up to 0.4 m and only where the space behind is free, until they no longer do; a
            turn already begun is not checked again (0: off). The cameras sit 0.12 m ahead of the
            axle and the stereo near limit is 0.21 m from them, so a turn nearer than 0.33 m to
            a wall is blind; counted as ``turn_backoffs``. On in the team defaults at 0.6 m: with
            ``turn_stall_time``, 2 of 78 robots above 0.10 m over 26 closed-loop seeds against 7
            of 78 without (docs/results.md).
        turn_stall_time: a robot turning on the spot whose heading moved less than 5° in this
            long is against something (a door jamb, a teammate: its body's corners swing out to
            0.33 m from its axle) and turns the other way round instead, once per turn; counted as
            ``blocked_turns`` (0: off) [s].
        start_delay: each robot stands still this long from its first pose on, so that the map
            is started from the known start poses: before a robot's first landmarks nothing can
            tell its particles' motion noise apart, and the landmarks it maps first fix the
            heading of everything mapped from them; a stereo frontend publishes a point once it
            is tracked over 3 frames [s].
    """

    coordinated: bool = True
    best_pair: bool = False
    beta: float = 1.0
    utility_range: float = 4.0
    occ_max: float = 0.65
    min_frontier_cells: int = 5
    robot_radius: float = 0.35
    target_reach: float = 0.0
    min_target_distance: float = 1.0
    avoid_others: bool = False
    keep_goal: float = 0.0
    goal_tolerance: float = 0.4
    replan_period: float = 4.0
    replan_new_area: float = 4.0
    progress_timeout: float = 8.0
    blacklist_radius: float = 0.5
    blacklist_period: float = 30.0
    recovery_time: float = 2.0
    recovery_speed: float = 0.15
    max_strikes: int = 3
    return_to_start: bool = False
    max_speed: float = 0.5
    max_turn_rate: float = 1.2
    lookahead: float = 0.4
    unknown_passable: bool = True
    unknown_cost: float = 1.0
    stall_time: float = 0.0
    bumper_range: float = 0.3
    keep_arc: bool = False
    keep_clear: float = 0.0
    path_clearance: float = 0.0
    open_side_turns: bool = False
    turn_clearance: float = 0.0
    turn_stall_time: float = 1.5
    start_delay: float = 0.0

    def __post_init__(self) -> None:
        if not self.unknown_cost >= 1.0:
            raise ValueError("unknown_cost must be >= 1")
        if not self.turn_clearance >= 0.0:
            raise ValueError("turn_clearance must be >= 0")
