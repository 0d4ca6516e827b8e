"""Exploration: value-iteration cost against the paper's update rule, frontiers, assignment,
A*, the occupancy grid, the explorer with its controller, and a seeded 2D run that explores and
stops."""

from dataclasses import replace

import numpy as np
import pytest

from mrslam_core.control.config import ControlConfig
from mrslam_core.control.controller import Controller
from mrslam_core.control.platform import PlatformConfig
from mrslam_core.exploration.assignment import assign_targets
from mrslam_core.exploration.config import ExplorationConfig, GridConfig
from mrslam_core.exploration.cost import travel_cost, value_iteration_reference
from mrslam_core.exploration.explorer import State
from mrslam_core.exploration.frontiers import frontier_cells, frontier_groups
from mrslam_core.exploration.grid import OccupancyGrid, Scan
from mrslam_core.exploration.planning import astar
from mrslam_core.pipelines.sim2d import TeamSim2D
from mrslam_core.sim.world import load_world

#: a robot small enough for the 0.2 m robot_radius of the room tests (corner_radius 0.14 m), its
#: camera's near limit no farther than that radius
SMALL = PlatformConfig(front=0.1, rear=0.1, width=0.2, camera_near=0.2)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_cost_equals_update_rule(seed):
    rng = np.random.default_rng(seed)
    prob = rng.uniform(0.0, 0.5, (9, 11))
    prob[rng.random((9, 11)) < 0.2] = 0.9  # untraversable cells
    prob[4, 5] = 0.1
    got = travel_cost(prob, np.array([[4, 5]]), occ_max=0.65, resolution=0.1)[0]
    want = value_iteration_reference(prob, (4, 5), occ_max=0.65, resolution=0.1)
    np.testing.assert_allclose(got, want, rtol=1e-9)
    assert np.isinf(got[prob > 0.65]).all()


def test_cost_hand_computed():
    prob = np.array([[0.5, 0.2, 0.9, 0.1]])
    cost = travel_cost(prob, np.array([[0, 0]]), 0.65, 1.0)[0, 0]
    np.testing.assert_allclose(cost[:2], [0.0, 0.2])  # stepping into a cell costs P(cell) · 1 m
    assert np.isinf(cost[2]) and np.isinf(cost[3])  # a wall cuts the corridor


def test_assignment_spreads_robots():
    targets = np.array([[0.0, 0.0], [0.5, 0.0], [10.0, 0.0]])
    cost = np.array([[0.1, 0.2, 2.0], [0.1, 0.2, 1.5]])  # both prefer the left cluster
    coord = assign_targets(targets, cost, beta=0.5, utility_range=4.0, coordinated=True)
    assert coord.tolist() == [0, 2]  # robot 2 sent to the other cluster
    selfish = assign_targets(targets, cost, beta=0.5, utility_range=4.0, coordinated=False)
    assert selfish.tolist() == [0, 0]
    # utility discount of eq. 8–9: P(d) = 1 − d / max_range
    unreachable = np.array([[np.inf, np.inf, np.inf]])
    assert assign_targets(targets, unreachable, 0.5, 4.0).tolist() == [-1]


def test_robots_are_assigned_in_list_order():
    # target 0 is beside robot 1; robot 0, listed first, is 1 m from it and 1.2 m from target 1
    targets = np.array([[0.0, 0.0], [8.0, 0.0]])
    cost = np.array([[1.0, 1.2], [0.1, 3.0]])
    # in list order (002 eq. 8) robot 0 takes target 0 (0.5 > 0.4); target 1 then scores -0.5 for
    # robot 1 and target 0 (utility 0) -0.05: both sent to target 0
    assert assign_targets(targets, cost, beta=0.5, utility_range=4.0).tolist() == [0, 0]
    # a robot that reaches nothing gets no target; the others are still assigned
    cost3 = np.vstack([cost, np.full(2, np.inf)])
    assert assign_targets(targets, cost3, 0.5, 4.0)[2] == -1
    assert assign_targets(np.zeros((0, 2)), np.zeros((2, 0)), 0.5, 4.0).tolist() == [-1, -1]


def test_frontiers_on_a_known_map():
    known = np.zeros((6, 8), bool)
    known[:, :4] = True
    free = known.copy()
    free[0, :] = False
    front = frontier_cells(free, known)
    assert np.argwhere(front).tolist() == [[r, 3] for r in range(1, 6)]
    assert len(frontier_groups(front, 5)) == 1 and len(frontier_groups(front, 6)) == 0


def test_astar_maze():
    grid = np.ones((5, 7), bool)
    grid[0:4, 2] = False
    grid[1:5, 4] = False
    path = astar(grid, (0, 0), (0, 6))
    assert path[0] == (0, 0) and path[-1] == (0, 6)
    assert all(grid[c] for c in path)
    steps = np.diff(np.array(path), axis=0)
    length = np.sum(np.where(np.abs(steps).sum(1) == 2, np.sqrt(2), 1.0))
    assert length == pytest.approx(6 + 4 * np.sqrt(2))  # down, through the gap, up and over
    assert astar(grid, (0, 0), (0, 2)) is None  # a blocked goal


def _at(grid: OccupancyGrid, layer: np.ndarray, x, y):
    """``layer`` (H, W) of ``grid`` at map points x, y [m] (broadcast), which must be on the grid."""
    cells = grid.cell_of(np.stack(np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float)), -1))
    assert grid.inside(cells).all()
    return layer[cells[..., 0], cells[..., 1]]


def test_grid_marks_free_and_hits():
    grid = OccupancyGrid(GridConfig(resolution=0.1))
    grid.insert(np.array([0.05, 1.05, 0.0]), Scan(np.array([0.0]), np.array([2.0]), np.array([True])))
    p = grid.probability()
    assert _at(grid, p, 2.05, 1.05) > 0.65  # the end cell at x = 2.05
    assert (_at(grid, p, np.arange(0.15, 1.9, 0.1), 1.05) < 0.4).all()  # the cells the beam crossed
    assert (grid.centre_of(np.argwhere(grid.observed))[:, 0] < 2.1).all()  # nothing beyond the end
    assert grid.observed.sum() == 21  # 20 crossed and the end


def test_a_hit_on_a_teammate_marks_no_obstacle_but_proves_the_space_before_it_free():
    """Two beams from (0.05, 1.05) along x and y: the one ending 0.4 m from a teammate at
    (2.45, 1.05) marks nothing occupied, but frees the cells it crossed, exactly as far as the
    hit; the other, 1.2 m from the teammate, is an obstacle. teammate_radius 0: both are."""
    beams = Scan(np.array([0.0, np.pi / 2]), np.array([2.0, 0.8]), np.array([True, True]))
    pose, mate = np.array([0.05, 0.05, 0.0]), np.array([[2.45, 0.05]])
    grid = OccupancyGrid(GridConfig(resolution=0.1, teammate_radius=0.45))
    grid.insert(pose, beams, mate)
    assert grid.occupied().sum() == 1 and _at(grid, grid.occupied(), 0.05, 0.85)  # the y beam's end
    assert _at(grid, grid.free(), np.arange(0.15, 2.0, 0.1), 0.05).all()
    assert (grid.centre_of(np.argwhere(grid.observed))[:, 0] < 2.0).all()  # nothing beyond the hit
    off = OccupancyGrid(GridConfig(resolution=0.1, teammate_radius=0.0))
    off.insert(pose, beams, mate)
    assert _at(off, off.occupied(), 2.05, 0.05) and off.occupied().sum() == 2
    assert beams.without_hits_near(pose, np.zeros((0, 2)), 0.45) is beams


def test_seeded_run_explores_small_world_and_stops():
    sim = TeamSim2D(load_world("small"), 2, ExplorationConfig(return_to_start=True), seed=3)
    curve = sim.run(300, stop_at=2.0)  # never stopped by coverage: only by the explorer
    assert curve[-1][1] >= 0.9
    assert sim.explorer.state is State.COMPLETE
    assert curve[-1][0] < 300  # stopped by itself, did not run out of time


def test_grid_from_the_frontends_obstacle_scan():
    from mrslam_core.frontend.obstacles import ObstacleScan

    obs = ObstacleScan(stamp_ns=0, angle_min=-0.1, angle_increment=0.1, ranges=np.array([1.0, np.inf]),
                       free_ranges=np.array([1.0, 2.0]), range_max=4.0, points=np.zeros((1, 2)))
    scan = Scan.from_obstacle_scan(obs)
    np.testing.assert_allclose(scan.bearings, [-0.05, 0.05])
    np.testing.assert_allclose(scan.ranges, [1.0, 2.0])
    assert scan.hit.tolist() == [True, False]
    grid = OccupancyGrid(GridConfig(resolution=0.1))
    grid.insert(np.zeros(3), scan)
    assert grid.occupied().sum() == 1 and grid.free().sum() > 20


def test_paths_cross_unobserved_cells():
    """Observed free: a U from the robot at (0.5, 0.5) east along y = 0.5, north along x = 5.5
    and back west along y = 3.5 to (0.5, 3.5); the straight way north (x = 0.5) was never
    observed, and the path takes it (unobserved cells are passable, at the unknown occupancy 0.5)."""
    from mrslam_core.exploration.explorer import planning_layers

    grid = OccupancyGrid(GridConfig(resolution=0.1), extent=((0.0, 0.0), (6.0, 4.0)))
    free = np.zeros(grid.shape, bool)
    free[1:10, 1:59] = True  # rows are y: y 0.1-1.0
    free[1:39, 50:59] = True  # x 5.0-5.9
    free[30:39, 1:59] = True  # y 3.0-3.9
    grid.observed[free] = True
    grid.logodds[free] = -3.0
    robot = np.array([0.5, 0.5, 0.0])
    passable, prob = planning_layers(grid, ExplorationConfig(robot_radius=0.2))
    start, goal = tuple(grid.cell_of(robot[:2])), tuple(grid.cell_of(np.array([0.5, 3.5])))
    path = np.array(astar(passable, start, goal))
    xy = grid.centre_of(path)
    assert len(path) == 31 and xy[:, 0].max() < 0.6  # straight north
    assert prob[20, 5] == 0.5 and prob[6, 6] < 0.1


def _open_room() -> OccupancyGrid:
    """6 m × 4 m, the west 4 m observed free, the rest unknown: a frontier along x = 4 m."""
    grid = OccupancyGrid(GridConfig(resolution=0.1), extent=((0.0, 0.0), (6.0, 4.0)))
    grid.observed[:, :40] = True
    grid.logodds[:, :40] = -3.0
    return grid


def test_a_robot_that_could_not_back_off_pulls_forward_next_time():
    """A robot wedged with a rear corner on a wall moves neither back nor round: its goal fails
    (no headway for progress_timeout), it backs off and does not move; at the next failure it
    recovers forward, then backward again. A robot that did move while backing off backs off."""
    from mrslam_core.exploration.explorer import Explorer

    cfg = ExplorationConfig(robot_radius=0.2, min_target_distance=0.5, progress_timeout=2.0)
    ctl = ControlConfig(recovery_time=1.0, platform=SMALL)

    def recoveries(moves_when_backing: bool) -> list[float]:
        """The sign of v at the start of each of the first three recoveries."""
        ex = Explorer(cfg, ["r"], Controller(ctl))
        pose = np.array([0.5, 2.0, 0.0])
        signs, t = [], 0.0
        while len(signs) < 3 and t < 30.0:
            started = ex.controller.recovery.until.get("r")
            v, w = ex.step(_open_room(), {"r": pose.copy()}, t)["r"]
            if ex.controller.recovery.until.get("r") != started:
                assert abs(v) == ctl.recovery_speed and w == 0.0
                signs.append(float(np.sign(v)))
            if v < 0 and moves_when_backing:
                pose[0] += v * 0.2
            t = round(t + 0.2, 6)
        return signs

    assert recoveries(moves_when_backing=False) == [-1.0, 1.0, -1.0]
    assert recoveries(moves_when_backing=True) == [-1.0, -1.0, -1.0]


def test_a_boxed_in_robot_recovers_and_blacklists_no_target():
    """robot1 at (1.0, 2.0) stands inside a ring of occupied cells 0.45-0.55 m from it (a teammate
    and obstacles mapped round it), robot2 in the open. A* from robot1 reaches no frontier: it
    backs off, and neither its target nor any other is blacklisted; robot2 gets a path."""
    from mrslam_core.exploration.explorer import Explorer

    grid = _open_room()
    rr, cc = np.mgrid[: grid.shape[0], : grid.shape[1]]
    ring = np.abs(np.hypot(rr - 20, cc - 10) - 5.0) <= 0.5
    grid.logodds[ring] = 3.0
    cfg = ExplorationConfig(robot_radius=0.2, min_target_distance=0.5)
    ex = Explorer(cfg, ["robot1", "robot2"], Controller(ControlConfig(platform=SMALL)))
    poses = {"robot1": np.array([1.05, 2.05, 0.0]), "robot2": np.array([2.5, 3.0, 0.0])}
    cmds = ex.step(grid, poses, 0.0)
    assert ex.controller.recovery.boxed_in == 1 and ex.blacklist == [] and ex.strikes == []
    assert ex.goals["robot1"] is None and ex.goals["robot2"].target[0] == pytest.approx(3.95)
    assert cmds["robot1"] == (-ControlConfig().recovery_speed, 0.0) and cmds["robot2"] != (0.0, 0.0)


def test_reaches_any_follows_the_region_that_holds_the_start():
    """Two rooms split by a wall column: cells on the start's side are reached, the others and
    cells off the grid are not; a start on a blocked cell reaches nothing."""
    from mrslam_core.exploration.explorer import reaches_any

    passable = np.ones((5, 7), bool)
    passable[:, 3] = False
    assert reaches_any(passable, (2, 0), np.array([[4, 2]]))
    assert not reaches_any(passable, (2, 0), np.array([[0, 4], [4, 6], [9, 1], [-1, 0]]))
    assert reaches_any(passable, (2, 0), np.array([[0, 4], [1, 1]]))
    passable[1, 3] = True  # a one-cell door; diagonal steps count
    assert reaches_any(passable, (0, 0), np.array([[2, 4]]))
    assert not reaches_any(passable, (2, 3), np.array([[2, 0]]))
    assert not reaches_any(passable, (0, 0), np.zeros((0, 2), np.int64))


def test_a_robot_that_follows_its_commands_reaches_the_frontier_without_a_strike():
    from mrslam_core.exploration.explorer import Explorer

    grid = _open_room()
    ex = Explorer(ExplorationConfig(robot_radius=0.2, min_target_distance=0.5), ["r"],
                  Controller(ControlConfig(platform=SMALL)))
    pose = np.array([0.5, 2.0, 0.0])
    for i in range(40):
        v, w = ex.step(grid, {"r": pose}, 0.2 * i)["r"]
        pose = pose + 0.2 * np.array([v * np.cos(pose[2]), v * np.sin(pose[2]), w])
    assert ex.strikes == [] and pose[0] > 2.0


def test_robots_stand_still_at_the_start_for_start_delay():
    """With start_delay 1 s a robot gets (0, 0) for its first second, counted from its own first
    pose (a robot heard later waits from then), and then drives to its goal."""
    from mrslam_core.exploration.explorer import Explorer

    grid = _open_room()
    ex = Explorer(ExplorationConfig(robot_radius=0.2, min_target_distance=0.5, start_delay=1.0), ["r"],
                  Controller(ControlConfig(platform=SMALL)))
    pose = np.array([0.5, 2.0, 0.0])
    cmds = [ex.step(grid, {"r": pose}, 5.0 + 0.2 * i)["r"] for i in range(7)]  # 5.0 ... 6.2 s
    assert all(c == (0.0, 0.0) for c in cmds[:5]), cmds
    assert cmds[5][0] > 0.1 and cmds[6][0] > 0.1, cmds
    assert ex.goals["r"] is not None  # the goal was planned while it waited


def test_the_follower_backs_away_then_turns_without_checking_again(wall_south):
    """A robot facing the wall whose path leads north: it backs at ``recovery_speed`` (counted
    once), keeps backing until 0.3 m from where it began, then turns on the spot."""
    from mrslam_core.exploration.explorer import Explorer, Goal

    slow = PlatformConfig(max_turn_rate=0.5)
    cfg = ControlConfig(turn_clearance=0.6, platform=slow)
    ex = Explorer(ExplorationConfig(), ["r"], Controller(cfg))
    ex.last_plan_s = 0.0
    grid = wall_south()
    ex.goals["r"] = Goal(np.array([2.0, 3.0]), np.array([[2.0, 1.5], [2.0, 2.0], [2.0, 2.5], [2.0, 3.0]]), 0.0)
    assert ex.step(grid, {"r": np.array([2.0, 1.02, -np.pi / 2])}, 0.2) == {"r": (-cfg.recovery_speed, 0.0)}
    assert ex.step(grid, {"r": np.array([2.0, 1.22, -np.pi / 2])}, 0.4) == {"r": (-cfg.recovery_speed, 0.0)}
    follower = ex.controller.follower
    v, w = ex.step(grid, {"r": np.array([2.0, 1.33, -np.pi / 2])}, 0.6)["r"]
    assert v == 0.0 and abs(w) == 0.5 and follower.turn_backoffs == 1 and follower.backing == {}
    v, w = ex.step(grid, {"r": np.array([2.0, 1.33, -np.pi / 2 + 0.1])}, 0.8)["r"]
    assert v == 0.0 and w == 0.5 and follower.turn_backoffs == 1
    off = Explorer(ExplorationConfig(), ["r"], Controller(ControlConfig(platform=slow)))
    off.last_plan_s, off.goals["r"] = 0.0, ex.goals["r"]
    assert off.step(grid, {"r": np.array([2.0, 1.02, -np.pi / 2])}, 0.2)["r"][0] == 0.0


def test_a_turn_on_the_spot_that_does_not_turn_goes_the_other_way_round_once(wall_south):
    """A robot at (2, 2) facing east whose path leads north-west turns left (0.5 rad/s). Its
    heading stays put: 1.5 s (``turn_stall_time``) after the turn began it is told to turn right,
    the long way, and keeps that direction; blocked that way too, it is not turned back again.
    A turn that moves is never reversed."""
    from mrslam_core.exploration.explorer import Explorer, Goal

    cfg = ControlConfig(platform=PlatformConfig(max_turn_rate=0.5))
    path = np.array([[1.5, 2.5], [1.0, 3.0], [0.5, 3.5]])
    grid = wall_south()
    ex = Explorer(ExplorationConfig(), ["r"], Controller(cfg))
    ex.last_plan_s, ex.goals["r"] = 0.0, Goal(np.array([0.5, 3.5]), path, 0.0)
    ex.known_at_plan = int(grid.observed.sum())  # no re-assignment: the map does not grow
    stuck = {"r": np.array([2.0, 2.0, 0.0])}
    assert ex.step(grid, stuck, 0.2)["r"] == (0.0, 0.5)
    assert ex.step(grid, stuck, 1.6)["r"] == (0.0, 0.5)  # 1.4 s: not yet
    assert ex.step(grid, stuck, 1.8)["r"] == (0.0, -0.5) and ex.controller.follower.blocked_turns == 1
    assert ex.step(grid, {"r": np.array([2.0, 2.0, -0.05])}, 2.0)["r"] == (0.0, -0.5)  # the long way
    assert ex.step(grid, {"r": np.array([2.0, 2.0, -0.05])}, 3.4)["r"] == (0.0, -0.5)
    assert ex.controller.follower.blocked_turns == 1

    free = Explorer(ExplorationConfig(), ["r"], Controller(cfg))
    free.last_plan_s, free.goals["r"] = 0.0, Goal(np.array([0.5, 3.5]), path, 0.0)
    free.known_at_plan = ex.known_at_plan
    for i, t in enumerate(np.arange(0.2, 3.0, 0.2)):
        assert free.step(grid, {"r": np.array([2.0, 2.0, 0.1 * i])}, t)["r"] == (0.0, 0.5)
    assert free.controller.follower.blocked_turns == 0


def test_the_explorer_inflates_by_at_least_the_platform_and_leaves_its_unseen_ground():
    """robot_radius below the platform's corner_radius is refused. A robot may leave through the
    inflated cells within max(robot_radius, camera_near) + 2 cells of it (``surroundings``): its
    camera never saw that ground."""
    from mrslam_core.exploration.explorer import Explorer, surroundings

    with pytest.raises(ValueError, match="corner_radius"):
        Explorer(ExplorationConfig(robot_radius=0.3), ["r"])  # the Pioneer's corners: 0.326 m
    grid = OccupancyGrid(GridConfig(resolution=0.1), extent=((0.0, 0.0), (6.0, 4.0)))
    near = surroundings(grid, np.array([2.05, 2.05]), 0.2)
    wide = surroundings(grid, np.array([2.05, 2.05]), 0.5)
    # the cells whose centres lie within 0.2 m + 2 cells = 4 cells of the robot's cell centre (49),
    # within 0.5 m + 2 cells = 7 cells (149)
    assert near.sum() == 49 and wide.sum() == 149 and (wide | near).sum() == wide.sum()


def test_a_robot_leaves_a_touched_corner_with_its_side_clear_of_it():
    """The simulated Pioneer at (1.05, 2.05) facing east touched a corner at its front right:
    the cell (1.25, 1.85) is occupied, everything else observed free; its goal lies 2.5 m east.
    Within the ground it may leave through (``surroundings``), the path keeps off the occupied
    cell and its 8 neighbours, every cell centre at least 2 cells (0.2 m, more than half the
    body's width) from it; beyond, the inflation by robot_radius holds."""
    from mrslam_core.exploration.explorer import Explorer, planning_layers

    grid = _open_room()
    corner = tuple(grid.cell_of(np.array([1.25, 1.85])))
    grid.logodds[corner] = 4.0
    cfg = ExplorationConfig(min_target_distance=0.5)
    ex = Explorer(cfg, ["r"], Controller(ControlConfig()))
    pose = np.array([1.05, 2.05, 0.0])
    passable, _ = planning_layers(grid, cfg)
    ex._set_goal("r", np.array([3.55, 2.05]), grid, passable, {"r": pose}, 0.0, np.array([[3.55, 2.05]]))
    path = ex.goals["r"].path
    clearance = np.linalg.norm(path - grid.centre_of(np.array(corner)), axis=1)
    assert clearance[1:].min() == pytest.approx(0.2) and clearance[1:].min() > PlatformConfig().width / 2
    assert (clearance[1:] < cfg.robot_radius).any()  # it does leave through inflated ground


def test_a_bumper_pressed_ahead_fails_the_goal_at_once_and_the_robot_backs_off():
    """A robot driving to a frontier whose bumper is pressed ahead of its axle (front right
    corner) gives the goal up at once (struck) and backs off; pressed behind the axle, or with no
    goal, nothing happens."""
    from mrslam_core.exploration.explorer import Explorer

    cfg = ExplorationConfig(robot_radius=0.2, min_target_distance=0.5)
    ctl = ControlConfig(platform=SMALL)
    ex = Explorer(cfg, ["r"], Controller(ctl))
    pose = np.array([1.05, 2.05, 0.0])
    ex.step(_open_room(), {"r": pose}, 0.0)
    assert ex.goals["r"] is not None
    grid = _open_room()
    # the rear: not pushing into it
    assert not ex.bumped(grid, "r", np.array([[-0.1, 0.1]]), {"r": pose}, 0.2)
    assert ex.bumped(grid, "r", np.array([[0.1, -0.1]]), {"r": pose}, 0.2)
    assert ex.goals["r"] is None and len(ex.blacklist) == 1 and ex.bumped_goals == 1
    v, w = ex.step(_open_room(), {"r": pose}, 0.4)["r"]
    assert (v, w) == (-ctl.recovery_speed, 0.0)
    assert not ex.bumped(grid, "r", np.array([[0.1, -0.1]]), {"r": pose}, 0.6)  # recovering: no goal to fail
