"""Robots that drive a fixed loop on their own (SimConfig.route): they stay on it, ignore
commands, and two runs move them identically (what fault tests compare)."""

import numpy as np
import pytest

from mrslam_core.sim import SimConfig, SimError, Simulation
from mrslam_core.sim.config import RouteConfig
from mrslam_core.sim.route import RouteDriver

# a 3.5 m × 0.7 m rectangle clear of the small world's furniture, counter-clockwise
SQUARE = (1.3, 1.8, 4.8, 1.8, 4.8, 2.5, 1.3, 2.5)


def _drive(seconds: float) -> np.ndarray:
    sim = Simulation(SimConfig(world="small", route=RouteConfig(waypoints=SQUARE)))
    sim.add_robot("robot1")
    out = []
    try:
        for _ in range(int(seconds / 0.5)):
            sim.set_command("robot1", -0.3, 1.0)  # ignored: the route steers
            sim.step(0.5)
            out.append(sim.ground_truth("robot1"))
    finally:
        sim.close()
    return np.array(out)


def test_robots_follow_the_loop_identically_in_two_runs():
    a, b = _drive(60.0), _drive(60.0)
    np.testing.assert_array_equal(a, b)
    loop = RouteDriver(RouteConfig(waypoints=SQUARE)).loop
    after = a[20:]  # from the start pose (1, 1) onto the loop first
    off = np.min(np.linalg.norm(after[:, None, :2] - loop[None], axis=2), axis=1)
    assert off.max() < 0.25, off.max()  # corners are cut by about the lookahead
    turned = np.sum(np.diff(np.unwrap(a[:, 2])))
    assert turned > 2 * np.pi, turned  # more than one lap (8.4 m at 0.3 m/s: 28 s), counter-clockwise
    assert a[:, 0].max() > 4.5 and a[:, 1].max() > 2.3 and a[:, 0].min() < 1.6


def test_bad_routes_are_named():
    with pytest.raises(SimError, match="route.waypoints"):
        RouteConfig(waypoints=(0.0, 0.0, 1.0))
    with pytest.raises(SimError, match="route.waypoints"):
        RouteConfig(waypoints=(0.0, 0.0, 1.0, 1.0))
    with pytest.raises(SimError, match="speed"):
        RouteConfig(waypoints=SQUARE, speed=0.0)
    with pytest.raises(SimError, match="start_interval"):
        RouteConfig(waypoints=SQUARE, start_interval=-1.0)


def test_robots_start_the_loop_one_interval_apart():
    cfg = SimConfig(world="small", route=RouteConfig(waypoints=SQUARE, start_interval=4.0))
    with Simulation(cfg) as sim:
        sim.add_robot("robot1")
        sim.add_robot("robot2")
        start = sim.ground_truth("robot2")
        sim.step(3.9)
        assert np.linalg.norm(sim.ground_truth("robot1")[:2] - [1.0, 1.0]) > 0.5
        np.testing.assert_array_equal(sim.ground_truth("robot2"), start)  # still waiting
        sim.step(2.0)
        assert np.linalg.norm(sim.ground_truth("robot2")[:2] - start[:2]) > 0.1
