"""The occupancy grid grows with what the scans reach: by whole blocks on the block lattice,
keeping every world cell's values, never shrinking; its memory bounded by the area seen.

Map frame: x east, y north [m]; grid cells (row, col) = (y, x); world cell (I, J) =
(⌊y / res⌋, ⌊x / res⌋), array cell = world cell − ``grid.offset``.
"""

import numpy as np
import pytest

from mrslam_core.control.config import ControlConfig
from mrslam_core.control.controller import Controller
from mrslam_core.control.platform import PlatformConfig
from mrslam_core.exploration.config import ExplorationConfig, GridConfig
from mrslam_core.exploration.coverage import explored_fraction
from mrslam_core.exploration.explorer import Explorer
from mrslam_core.exploration.grid import OccupancyGrid, Scan
from mrslam_core.pipelines.sim2d import SensorConfig, TeamSim2D
from mrslam_core.sim.world import load_world


def _beam_to(pose: np.ndarray, end: tuple[float, float], hit: bool = True) -> Scan:
    """One beam from ``pose`` (x, y, θ) ending at ``end`` (x, y) [m]."""
    d = np.asarray(end, float) - pose[:2]
    return Scan(np.array([np.arctan2(d[1], d[0]) - pose[2]]), np.array([np.hypot(*d)]), np.array([hit]))


def _window(big: OccupancyGrid, grid: OccupancyGrid) -> tuple[slice, slice]:
    """The cells of ``big`` that are ``grid``'s cells (same world cells)."""
    r0, c0 = grid.offset - big.offset
    return slice(r0, r0 + grid.shape[0]), slice(c0, c0 + grid.shape[1])


def test_a_scan_ending_at_minus_5_30_grows_the_grid_by_whole_blocks_and_keeps_what_was_seen():
    cfg = GridConfig(resolution=0.1, block=4.0)  # 40-cell blocks
    grid = OccupancyGrid(cfg)
    assert grid.shape == (0, 0) and not grid.observed.any()
    pose = np.array([0.55, 0.55, 0.0])
    grid.insert(pose, Scan(np.array([0.0]), np.array([2.0]), np.array([True])))  # along y = 0.55 to x = 2.55
    # cells passed: row 5, cols 5..24 (x 0.55..2.45), hit col 25; with their neighbours rows 4..6,
    # cols 4..25: one block, x and y in [0, 4) m
    assert grid.shape == (40, 40) and grid.offset.tolist() == [0, 0] and grid.origin.tolist() == [0.0, 0.0]
    before_lo, before_obs = grid.logodds.copy(), grid.observed.copy()
    assert before_obs.sum() == 21 and grid.occupied()[5, 25]

    second = _beam_to(np.array([0.05, 1.05, 0.0]), (-5.0, 30.0))
    grid.insert(np.array([0.05, 1.05, 0.0]), second)
    # the end cell (-5.0, 30.0) is world cell (300, -50); the passed cells reach x -4.95, y 29.95
    # (world (299, -50)) and their neighbours col -51: rows grow to 320 (y 32 m), cols from -80 (x -8 m)
    assert grid.offset.tolist() == [0, -80] and grid.shape == (320, 120)
    np.testing.assert_allclose(grid.origin, [-8.0, 0.0])
    end = grid.cell_of(np.array([-5.0, 30.0]))
    assert end.tolist() == [300, 30] and grid.occupied()[300, 30]
    # what was seen before is where it was in the world, unchanged
    old = grid.logodds[0:40, 80:120], grid.observed[0:40, 80:120]
    first_scan = np.zeros((40, 40), bool)
    first_scan[5, 5:26] = True
    np.testing.assert_array_equal(old[0][first_scan], before_lo[first_scan])
    assert old[1][first_scan].all()
    np.testing.assert_allclose(grid.centre_of(grid.cell_of(np.array([2.55, 0.55]))), [2.55, 0.55])
    assert grid.occupied()[tuple(grid.cell_of(np.array([2.55, 0.55])))]

    # the same two scans into a grid allocated up front: equal at every world cell
    big = OccupancyGrid(cfg, extent=((-10.0, -2.0), (6.0, 34.0)))
    big.insert(pose, Scan(np.array([0.0]), np.array([2.0]), np.array([True])))
    big.insert(np.array([0.05, 1.05, 0.0]), second)
    assert big.shape == (360, 160)  # never grew: everything fell inside
    win = _window(big, grid)
    np.testing.assert_array_equal(big.logodds[win], grid.logodds)
    np.testing.assert_array_equal(big.observed[win], grid.observed)
    assert big.observed.sum() == grid.observed.sum()


def test_the_grid_never_shrinks_and_its_edges_stay_on_the_block_lattice():
    rng = np.random.default_rng(4)
    cfg = GridConfig(resolution=0.1, block=2.0)
    grid = OccupancyGrid(cfg)
    lo = hi = None
    for k in range(60):
        pose = np.array([*rng.uniform(-15, 15, 2), rng.uniform(-np.pi, np.pi)])
        n = int(rng.integers(1, 30))
        grid.insert(pose, Scan(rng.uniform(-np.pi, np.pi, n), rng.uniform(0.2, 6.0, n), rng.random(n) < 0.6))
        start, stop = grid.offset.copy(), grid.offset + np.array(grid.shape)
        if lo is not None:
            assert (start <= lo).all() and (stop >= hi).all(), k
        lo, hi = start, stop
        assert (start % 20 == 0).all() and (stop % 20 == 0).all()
        # a scan inside what was seen changes neither the size nor the origin
        grid.insert(pose, Scan(np.array([0.0]), np.array([0.15]), np.array([False])))
        assert grid.offset.tolist() == start.tolist() and (grid.offset + np.array(grid.shape)).tolist() == stop.tolist()


def test_every_passed_cell_keeps_its_neighbours_on_the_grid():
    """A free cell at the edge of what was seen borders unknown cells ON the grid, so it is a
    frontier wherever the arrays end."""
    grid = OccupancyGrid(GridConfig(resolution=0.1, block=1.0))
    grid.insert(np.array([0.05, 0.05, np.pi]), Scan(np.array([0.0]), np.array([0.95]), np.array([False])))
    # free cells x -0.85..0.05 (world cols -9..0), row 0; the block lattice gives x [-1, 1), y [-1, 1)
    assert grid.offset.tolist() == [-10, -10] and grid.shape == (20, 20)
    free = np.argwhere(grid.free())
    assert len(free) and (free >= 1).all() and (free <= np.array(grid.shape) - 2).all()
    from mrslam_core.exploration.frontiers import frontier_cells

    assert frontier_cells(grid.free(), grid.observed)[grid.free()].all()  # a thin line: all frontier


def test_block_must_be_whole_cells():
    with pytest.raises(ValueError, match="whole multiple"):
        GridConfig(resolution=0.1, block=0.25)
    with pytest.raises(ValueError, match="finite and > 0"):
        GridConfig(resolution=0.1, block=0.0)
    with pytest.raises(ValueError, match="finite and > 0"):
        GridConfig(resolution=0.1, block=float("inf"))
    assert OccupancyGrid(GridConfig(resolution=0.05, block=0.3)).block_cells == 6


def test_the_grid_covers_a_40_by_30_m_building_with_memory_bounded_by_what_was_seen():
    """Scans (360°, 180 beams, 8 m, ray-cast on the world's 5 cm raster, no rendering) from every
    free point of a 2 m lattice over the hall40x30 world, into a grid that starts empty."""
    world = load_world("hall40x30")
    assert world.size == (40.0, 30.0)
    cfg = GridConfig(resolution=0.1, block=1.0)
    sim = TeamSim2D(world, 1, ExplorationConfig(), SensorConfig(fov=2 * np.pi, beams=180, max_range=8.0), grid=cfg)
    grid = sim.grid
    big = OccupancyGrid(cfg, extent=((-2.0, -2.0), (42.0, 32.0)))  # the same scans, allocated up front
    xs, ys = np.meshgrid(np.arange(1.0, 40.0, 2.0), np.arange(1.0, 30.0, 2.0))
    poses = [np.array([x, y, 0.0]) for x, y in zip(xs.ravel(), ys.ravel()) if sim._free(np.array([x, y]))]
    assert len(poses) == 266  # of 300: the rest stand in walls, furniture or pillars
    extents = []
    for pose in poses:
        scan = sim.scan(pose)
        grid.insert(pose, scan)
        big.insert(pose, scan)
        extents.append((*grid.offset, *(grid.offset + grid.shape)))
    extents = np.array(extents)
    assert len(np.unique(extents, axis=0)) > 5  # it grew, many times
    assert (np.diff(extents[:, :2], axis=0) <= 0).all() and (np.diff(extents[:, 2:], axis=0) >= 0).all()

    # the world: every free cell of it (5 cm raster) lies on the grid, and every reachable one was seen
    h, w = sim.truth.shape
    centres = (np.stack(np.meshgrid(np.arange(w), np.arange(h)), -1) + 0.5) * sim.res
    cells = grid.cell_of(centres[~sim.truth])
    assert grid.inside(cells).all()
    # of the reachable free cells, a handful in corners behind furniture met no ray: 16 of 420 992
    # at 5 cm; the coverage measure of the pipelines, on its 0.1 m raster of the world: 7 of 114 217
    assert round((1 - sim.explored_fraction()) * sim.reachable.sum()) == 16
    truth_free = world.reachable_free(cfg.resolution)
    fraction = explored_fraction(grid.observed, grid.origin, grid.res, truth_free, cfg.resolution)
    assert truth_free.sum() == 114_217 and round((1 - fraction) * truth_free.sum()) == 7

    # growth lost and shifted nothing: equal to the grid allocated up front at every world cell
    win = _window(big, grid)
    np.testing.assert_array_equal(big.logodds[win], grid.logodds)
    np.testing.assert_array_equal(big.observed[win], grid.observed)
    assert big.observed.sum() == grid.observed.sum() > 100_000

    # memory: the observed cells span the world's 300 × 400 cells exactly; the arrays are that box
    # with the passed cells' neighbours, rounded out to 1 m blocks: y [-1, 31) m, x [-1, 40) m
    seen = np.argwhere(grid.observed) + grid.offset
    assert seen.min(axis=0).tolist() == [0, 0] and seen.max(axis=0).tolist() == [299, 399]
    assert grid.offset.tolist() == [-10, -10] and grid.shape == (320, 410)
    block = grid.block_cells
    span = seen.max(axis=0) - seen.min(axis=0) + 1
    assert grid.logodds.size == 131_200 <= np.prod(span + 2 * block) == 134_400  # seen box + one block each side
    assert grid.logodds.nbytes + grid.observed.nbytes == 5 * 131_200


def test_the_explorer_keeps_its_goal_when_the_grid_grows_between_steps():
    """A 6 × 4 m room walled on the west, south and north, seen up to x = 4 m: robot1 plans to the
    frontier at x = 4 m; the grid then grows 10 m to the west and south (every array index
    shifts by 100) and the next re-assignment gives the same target and path in metres."""
    grid = OccupancyGrid(GridConfig(resolution=0.1, block=1.0), extent=((0.0, 0.0), (6.0, 4.0)))
    grid.observed[:, :40] = True
    grid.logodds[:, :40] = -3.0
    grid.logodds[[0, 39], :40] = grid.logodds[:, 0] = 3.0  # walls
    small = PlatformConfig(front=0.1, rear=0.1, width=0.2, camera_near=0.2)  # fits the 0.2 m robot_radius
    ex = Explorer(ExplorationConfig(robot_radius=0.2), ["robot1"], Controller(ControlConfig(platform=small)))
    pose = {"robot1": np.array([1.0, 2.0, 0.0])}
    ex.step(grid, pose, 0.0)
    goal = ex.goals["robot1"]
    assert goal is not None and goal.target[0] > 3.5
    grid.cover(np.array([-10.0, -10.0]), np.array([0.0, 0.0]))
    assert grid.offset.tolist() == [-100, -100] and grid.shape == (140, 160)
    ex.step(grid, pose, 0.2)  # not due: the goal held in metres still drives the robot
    assert ex.goals["robot1"] is goal
    ex.step(grid, pose, 4.0)  # due (replan_period), before progress_timeout: planned afresh on the grown grid
    again = ex.goals["robot1"]
    assert again is not goal
    np.testing.assert_allclose(again.target, goal.target)
    np.testing.assert_allclose(again.path, goal.path)


def test_beams_or_poses_that_are_not_finite_mark_nothing_and_grow_nothing():
    grid = OccupancyGrid(GridConfig(resolution=0.1, block=1.0))
    beams = Scan(np.array([0.0, np.nan, 0.5]), np.array([1.0, 2.0, np.inf]), np.array([True, True, True]))
    grid.insert(np.array([0.55, 0.55, 0.0]), beams)
    assert grid.shape == (10, 20) and grid.observed.sum() == 11  # the first beam only: x 0.55..1.45 passed, 1.55 hit
    grid.insert(np.array([np.nan, 0.0, 0.0]), Scan(np.array([0.0]), np.array([1.0]), np.array([True])))
    assert grid.shape == (10, 20) and grid.observed.sum() == 11


def test_a_hit_counts_by_the_chance_its_range_puts_the_surface_in_its_cell():
    from math import erf, exp, log, sqrt

    cfg = GridConfig(range_noise=0.011)
    grid = OccupancyGrid(cfg)
    p = 1.0 / (1.0 + exp(-cfg.hit))
    for r in (0.5, 2.0, 6.0):
        sigma = 0.011 * r * r
        q = 0.5 + (p - 0.5) * erf(0.1 / (2.0 * sqrt(2.0) * sigma))
        assert grid.hit_logodds(np.array([r]))[0] == pytest.approx(log(q / (1.0 - q)), rel=1e-12)
    assert OccupancyGrid(GridConfig()).hit_logodds(np.array([0.5, 6.0])) == pytest.approx([cfg.hit, cfg.hit])
    # a near hit makes its cell occupied at once; one 6 m away (σ 0.40 m, 0.081 log-odds) needs 8
    occ = np.log(cfg.occupied_above / (1 - cfg.occupied_above))
    pose = np.array([0.05, 0.05, 0.0])
    for end, times in (((1.05, 0.05), 1), ((0.05, 6.05), int(np.ceil(occ / grid.hit_logodds(np.array([6.0]))[0])))):
        fresh = OccupancyGrid(cfg)
        for k in range(times):
            fresh.insert(pose, _beam_to(pose, end))
            assert fresh.occupied()[tuple(fresh.cell_of(np.array([end]))[0])] == (k == times - 1), (end, k)
    assert times == 8


def test_range_noise_must_be_finite_and_not_negative():
    for bad in (-0.01, float("inf"), float("nan")):
        with pytest.raises(ValueError, match="range_noise"):
            GridConfig(range_noise=bad)


def test_a_bumper_touch_is_occupied_for_good_and_beams_do_not_clear_it():
    """A robot at (1, 2) facing north (+y) touches at (0.18, 0.19) in base_link: the map point
    (0.81, 2.18), cell centre (0.85, 2.15). Beams through the cell leave it occupied; a touch
    within ``teammate_radius`` of a teammate marks nothing."""
    grid = OccupancyGrid(GridConfig())
    pose = np.array([1.0, 2.0, np.pi / 2])
    assert grid.touch(pose, np.array([[0.18, 0.19], [0.18, 0.19]]), np.array([[5.0, 5.0]])) == 1
    np.testing.assert_allclose(grid.centre_of(np.argwhere(grid.occupied())), [[0.85, 2.15]], atol=1e-9)
    for _ in range(20):
        grid.insert(np.array([0.0, 2.15, 0.0]), _beam_to(np.array([0.0, 2.15, 0.0]), (3.0, 2.15), hit=False))
    np.testing.assert_allclose(grid.centre_of(np.argwhere(grid.occupied())), [[0.85, 2.15]], atol=1e-9)
    assert grid.free()[tuple(grid.cell_of(np.array([0.55, 2.15])))]  # its neighbours on the beam are free
    # the touch was on a teammate standing 0.3 m away: nothing new
    assert grid.touch(pose, np.array([[0.0, -0.3]]), np.array([[1.3, 2.0]])) == 0
    assert grid.occupied().sum() == 1
