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
        range_noise: a hit's range error grows as ``range_noise`` · range² (σ [m]): a stereo
            rig's depth noise, σd / (f·b), σd the disparity noise [px], f the focal length [px],
            b the baseline [m] [1/m]. A hit then adds logit(½ + (p − ½)·P) to its end cell, p the
            probability of ``hit``, P = erf(resolution / (2√2 σ)) the chance that the surface
            lies in that cell along the beam, instead of ``hit``: 6 m from the simulated 0.12 m
            rig (σ 0.39 m) a hit is one of about ten cells, 1 m from it one cell. 0: exact
            ranges (a laser scanner), every hit ``hit``.
        teammate_radius: a beam ending within this of another robot's position (base_link, map
            frame) ended on that robot's body: it proves the space up to it free and marks no
            obstacle. Robots see each other; mapped, a teammate that drove on leaves an obstacle
            where no one looks again, and inflated for planning it sealed a start room's door
            (docs/results.md). Larger than the platform's ``corner_radius``
            (``ControlConfig.platform``); 0: off [m].
    """

    resolution: float = 0.1
    block: float = 1.0
    hit: float = 0.85
    miss: float = -0.7
    clamp: float = 4.0
    free_below: float = 0.4
    occupied_above: float = 0.65
    range_noise: float = 0.0
    teammate_radius: float = 0.45

    def __post_init__(self) -> None:
        if not (0 < self.resolution < float("inf") and 0 < self.block < float("inf")):
            raise ValueError(f"resolution and block must be finite and > 0, got {self.resolution} and {self.block}")
        if not 0.0 <= self.range_noise < float("inf"):
            raise ValueError(f"range_noise must be finite and >= 0, got {self.range_noise}")
        cells = self.block / self.resolution
        if not (round(cells) >= 1 and abs(cells - round(cells)) < 1e-6):
            raise ValueError(f"block {self.block} m must be a whole multiple (>= 1) of resolution {self.resolution} m")


@dataclass(frozen=True)
class ExplorationConfig:
    """Frontier exploration (002 section V after Burgard et al. 2005): targets, paths, progress.
    How the robots follow their paths is :class:`~mrslam_core.control.config.ControlConfig`'s.

    Attributes:
        coordinated: discount the utility of targets near already assigned ones (eq. 8–9);
            False sends every robot to its own best frontier.
        beta: weight of the travel cost V in argmax(U − β·V).
        utility_range: max_range of the discount P(d) = 1 − d/max_range [m].
        occ_max: cells with occupancy probability above this are not traversable.
        min_frontier_cells: smaller frontier groups are ignored.
        robot_radius: obstacles are inflated by this for planning; at least the platform's
            ``corner_radius`` (``ControlConfig.platform``, checked by the
            :class:`~mrslam_core.exploration.explorer.Explorer`) [m].
        min_target_distance: frontier targets closer than this to the robot are skipped (the
            unknown just behind a robot with a forward-looking sensor is not worth a goal) [m].
        goal_tolerance: a goal counts as reached within this distance [m].
        replan_period: re-assign targets at least this often [s].
        replan_new_area: re-assign sooner (at most once a second) when this much new area has
            been mapped since the last assignment [m²].
        progress_timeout: a goal with no progress for this long is blacklisted, and the robot
            recovers (``ControlConfig.recovery_time``) [s].
        blacklist_radius: frontier cells within this of a blacklisted goal are skipped [m].
        blacklist_period: a failed goal is skipped for this long, then tried again [s].
        max_strikes: after this many failures at one place it is skipped for good.
        return_to_start: drive back to the start pose once exploration is complete.
        start_delay: each robot stands still this long from its first pose on, so that the map
            is started from the known start poses: before a robot's first landmarks nothing can
            tell its particles' motion noise apart, and the landmarks it maps first fix the
            heading of everything mapped from them; a stereo frontend publishes a point once it
            is tracked over 3 frames [s].
    """

    coordinated: bool = True
    beta: float = 1.0
    utility_range: float = 4.0
    occ_max: float = 0.65
    min_frontier_cells: int = 5
    robot_radius: float = 0.35
    min_target_distance: float = 1.0
    goal_tolerance: float = 0.4
    replan_period: float = 4.0
    replan_new_area: float = 4.0
    progress_timeout: float = 8.0
    blacklist_radius: float = 0.5
    blacklist_period: float = 30.0
    max_strikes: int = 3
    return_to_start: bool = False
    start_delay: float = 0.0
