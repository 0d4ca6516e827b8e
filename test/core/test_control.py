"""Drive commands: pure pursuit, the turn-on-the-spot rules of the path follower (open side,
backing away, blocked turns), stall detection and recovery, and the platform's numbers in each."""

import ast
from pathlib import Path

import numpy as np
import pytest

from mrslam_core.control.config import ControlConfig
from mrslam_core.control.controller import Controller
from mrslam_core.control.follower import Follower, sweep_clearance
from mrslam_core.control.platform import PlatformConfig
from mrslam_core.control.pursuit import pure_pursuit
from mrslam_core.control.recovery import Recovery


def test_pure_pursuit_drives_the_arc_through_the_lookahead_point():
    """From the origin facing east, the path point (0.3, 0.4) is the first 0.5 m away (the
    lookahead), 53.13° to the left: v = 0.5 m/s · cos 53.13° = 0.3 m/s on the arc through it,
    curvature 2 · sin 53.13° / 0.5 m = 3.2 /m, ω = 0.96 rad/s. With 0.48 rad/s at most the turn
    rate is clipped (the robot swings wide), or with ``keep_arc`` the speed drops to 0.15 m/s."""
    pose, path = np.zeros(3), np.array([[0.0, 0.0], [0.15, 0.2], [0.3, 0.4], [0.6, 0.8]])
    v, w, idx = pure_pursuit(pose, path, 0.5, 0.5, 1.2)
    assert idx == 2 and v == pytest.approx(0.3) and w == pytest.approx(0.96)
    v, w, _ = pure_pursuit(pose, path, 0.5, 0.5, 0.48)
    assert v == pytest.approx(0.3) and w == pytest.approx(0.48)
    v, w, _ = pure_pursuit(pose, path, 0.5, 0.5, 0.48, keep_arc=True)
    assert v == pytest.approx(0.15) and w == pytest.approx(0.48)
    # 90° off (more than 60°): on the spot, at twice the bearing, clipped
    assert pure_pursuit(pose, np.array([[0.0, 0.0], [0.0, 1.0]]), 0.5, 0.5, 1.2) == (0.0, 1.2, 1)
    v, w, _ = pure_pursuit(pose, np.array([[0.0, 0.0], [-1.0, 0.0]]), 0.5, 0.5, 1.2)
    assert v == 0.0 and abs(w) == 1.2  # behind: either way round


def test_pure_pursuit_with_keep_arc_drives_the_arc_it_aims_at_when_the_turn_rate_saturates():
    """Into a 90° corner (a door off a corridor) at 0.35 m/s with 0.5 rad/s at most: with
    ``keep_arc`` the speed drops so the commanded arc is the pure-pursuit arc; clipping the turn
    rate alone swings the robot 0.157 m off the path (0.7 m turning radius)."""
    path = np.vstack([np.column_stack([np.arange(0.0, 2.0, 0.05), np.zeros(40)]),
                      np.column_stack([np.full(41, 2.0), np.arange(0.0, 2.05, 0.05)])])
    worst = {}
    for keep in (True, False):
        pose, worst[keep], dt = np.zeros(3), 0.0, 0.05
        for _ in range(600):
            v, w, _ = pure_pursuit(pose, path, 0.4, 0.35, 0.5, keep_arc=keep)
            assert abs(w) <= 0.5 + 1e-12 and 0.0 <= v <= 0.35
            pose = pose + dt * np.array([v * np.cos(pose[2]), v * np.sin(pose[2]), w])
            worst[keep] = max(worst[keep], float(np.linalg.norm(path - pose[:2], axis=1).min()))
            if np.linalg.norm(pose[:2] - path[-1]) < 0.1:
                break
        assert np.linalg.norm(pose[:2] - path[-1]) < 0.1
    assert worst[True] < 0.12 and worst[False] > 0.15, worst


def test_the_follower_drives_at_the_platforms_limits(wall_south):
    """The same path, two platforms: the follower's speed and turn rate are the platform's."""
    path = np.array([[0.0, 0.0], [0.15, 0.2], [0.3, 0.4]])
    slow = PlatformConfig(max_speed=0.25, max_turn_rate=0.5)
    for platform, want in ((PlatformConfig(), (0.3, 0.96)), (slow, (0.15, 0.48))):
        follower = Follower(ControlConfig(platform=platform))
        v, w = follower.command("r", wall_south(), np.array([2.0, 2.0, 0.0]), path + [2.0, 2.0], 0.0)
        assert (v, w) == pytest.approx(want)


def test_sweep_clearance_is_the_nearest_occupied_cell_the_turn_looks_at(wall_south):
    """From (2, 1.02) facing east, turning right by 90° looks straight at the wall 0.32 m south:
    the first sample inside its cells is 0.35 m out (samples every 0.05 m); turning left sees
    nothing within 1 m; a turn of 30° right meets the wall 0.32 / sin 30° = 0.64 m out (sample
    0.65 m)."""
    grid = wall_south()
    pose = np.array([2.0, 1.02, 0.0])
    occ = grid.occupied()
    assert sweep_clearance(grid, occ, pose, -np.pi / 2, 1.0) == pytest.approx(0.35)
    assert sweep_clearance(grid, occ, pose, np.pi / 2, 1.0) == 1.0
    assert sweep_clearance(grid, occ, pose, -np.radians(30), 1.0) == pytest.approx(0.65)


def test_a_turn_on_the_spot_beside_a_wall_goes_round_the_open_side(wall_south):
    """A robot 0.3 m north of a wall, facing west-south-west (-150°), must turn 150° to face its
    aim due east. The short way (left, through south) sweeps the camera across the wall, so it
    turns right, through north; it keeps turning right where the aim is 170° to its left, and
    drives once the aim is ahead. Without the wall, or for a turn of 120° or less, the short way."""
    rate = 0.5
    cfg = ControlConfig(open_side_turns=True, platform=PlatformConfig(max_turn_rate=rate))
    f = Follower(cfg)
    grid, aim = wall_south(), np.array([3.0, 1.0])
    pose = np.array([2.0, 1.0, np.radians(-150.0)])
    assert f._turn_side("r", grid, pose, aim, 0.0, rate) == -rate and f.long_turns == 1
    pose[2] = np.radians(-170.0)  # turned 20° right: the aim is now 170° to the left
    assert f._turn_side("r", grid, pose, aim, 0.0, rate) == -rate
    pose[2] = np.radians(40.0)  # 2·40° > rate: still clipped
    assert f._turn_side("r", grid, pose, aim, 0.0, -rate) == -rate
    assert f._turn_side("r", grid, pose, aim, 0.2, -0.1) == -0.1 and f.spin == {}  # driving: as pure pursuit says
    free = wall_south()
    free.logodds[6, :] = -3.0
    f = Follower(cfg)
    assert f._turn_side("r", free, np.array([2.0, 1.0, np.radians(-150.0)]), aim, 0.0, rate) == rate
    assert f._turn_side("r", grid, np.array([2.0, 1.0, np.radians(-115.0)]), aim, 0.0, rate) == rate
    assert f.long_turns == 0


def test_the_controller_sends_a_turn_past_a_wall_the_long_way_round(wall_south):
    """The same robot given a path due east: pure pursuit turns it left (150° to go, on the spot at
    the full rate), the controller right; with a 160° threshold for ``open_side_turn`` left."""
    grid, pose = wall_south(), {"r": np.array([2.0, 1.0, np.radians(-150.0)])}
    path = {"r": np.array([[2.0, 1.0], [2.5, 1.0], [3.0, 1.0]])}
    slow = PlatformConfig(max_turn_rate=0.5)
    assert Controller(ControlConfig(platform=slow)).step(grid, pose, path, 0.0) == {"r": (0.0, 0.5)}
    ctl = Controller(ControlConfig(open_side_turns=True, platform=slow))
    assert ctl.step(grid, pose, path, 0.0) == {"r": (0.0, -0.5)} and ctl.counters()["long_turns"] == 1
    wide = Controller(ControlConfig(open_side_turns=True, open_side_turn=float(np.radians(160.0)), platform=slow))
    assert wide.step(grid, pose, path, 0.0) == {"r": (0.0, 0.5)}


def test_a_robot_facing_a_wall_backs_away_only_as_far_as_the_room_behind_allows(wall_south):
    """From (2, 1.02) facing the wall 0.32 m south, a turn right by 90° sweeps its heading within
    0.35 m of the wall (first sample inside its cells, rays every 10° from −100°). With
    ``turn_clearance`` 0.6 m it backs 0.3 m: the −100° ray then meets the wall 0.63 m out, the first
    sample there at 0.65 m, beyond 0.6 m. With a wall 0.58 m behind it (first sample inside at
    0.6 m, room 0.6 − 0.265 − 0.1 m: the platform's ``rear`` and ``back_margin``), only 0.2 m,
    which gains 0.2 m; for a body 0.1 m shorter behind the axle, 0.3 m. With a wall 0.28 m behind,
    not at all; with the turn clear, not at all."""
    f = Follower(ControlConfig(turn_clearance=0.6))
    pose = np.array([2.0, 1.02, -np.pi / 2])
    assert f.backoff(wall_south(), pose, -np.pi / 2) == pytest.approx(0.3)
    behind = wall_south()
    behind.logodds[16, :] = 3.0  # cells y 1.6-1.7
    assert f.backoff(behind, pose, -np.pi / 2) == pytest.approx(0.2)
    short = Follower(ControlConfig(turn_clearance=0.6, platform=PlatformConfig(rear=0.165)))
    assert short.backoff(behind, pose, -np.pi / 2) == pytest.approx(0.3)
    behind.logodds[13, :] = 3.0  # cells y 1.3-1.4
    assert f.backoff(behind, pose, -np.pi / 2) == 0.0
    assert f.backoff(wall_south(), np.array([2.0, 1.02, np.pi / 2]), np.pi / 2) == 0.0


def test_the_controller_backs_the_distance_then_turns(wall_south):
    """The robot facing the wall whose path leads north backs at ``recovery_speed`` until it is
    0.3 m from where it began (0.29 m: still backing), then turns on the spot; the backing is
    counted once."""
    cfg = ControlConfig(turn_clearance=0.6, recovery_speed=0.2, platform=PlatformConfig(max_turn_rate=0.5))
    ctl, grid = Controller(cfg), wall_south()
    path = {"r": np.array([[2.0, 1.5], [2.0, 2.0], [2.0, 2.5], [2.0, 3.0]])}
    for t, y in ((0.0, 1.02), (0.2, 1.06), (1.2, 1.31)):
        assert ctl.step(grid, {"r": np.array([2.0, y, -np.pi / 2])}, path, t) == {"r": (-0.2, 0.0)}
    v, w = ctl.step(grid, {"r": np.array([2.0, 1.33, -np.pi / 2])}, path, 1.4)["r"]
    assert v == 0.0 and abs(w) == 0.5 and ctl.follower.backing == {} and ctl.counters()["turn_backoffs"] == 1


def test_a_turn_that_does_not_turn_is_reversed_after_the_stall_time(wall_south):
    """A robot turning on the spot whose heading moves 4° in 1 s (``turn_stall_time``, with 5° as
    ``turn_stall_angle``) is sent the other way round; one whose heading moves 6° is not; with a
    3° angle neither is."""
    path = np.array([[2.0, 2.0], [1.5, 2.5], [1.0, 3.0]])  # 135° to the left: on the spot
    for moved, angle, reversed_ in ((4.0, 5.0, True), (6.0, 5.0, False), (4.0, 3.0, False)):
        f = Follower(ControlConfig(turn_stall_time=1.0, turn_stall_angle=float(np.radians(angle))))
        assert f.command("r", wall_south(), np.array([2.0, 2.0, 0.0]), path, 0.0) == (0.0, 1.2)
        v, w = f.command("r", wall_south(), np.array([2.0, 2.0, np.radians(moved)]), path, 1.0)
        assert (v, w) == ((0.0, -1.2) if reversed_ else (0.0, 1.2)), (moved, angle)
        assert f.blocked_turns == int(reversed_)


def test_a_recovery_drives_straight_back_then_forward_if_it_did_not_move():
    rec = Recovery(ControlConfig(recovery_time=2.0, recovery_speed=0.2))
    pose = np.array([1.0, 2.0, 0.0])
    rec.start("r", pose, 10.0)
    assert rec.active("r", 11.9) and not rec.active("r", 12.0) and rec.command("r") == (-0.2, 0.0)
    rec.start_boxed_in("r", pose + [0.04, 0.0, 0.0], 20.0)  # moved 4 cm: stuck, the other way
    assert rec.command("r") == (0.2, 0.0) and rec.boxed_in == 1
    rec.start("r", pose + [0.2, 0.0, 0.0], 30.0)  # moved: back off again
    assert rec.command("r") == (-0.2, 0.0)


def test_the_controller_drives_a_recovery_unless_everyone_halts(wall_south):
    """robot1 at (0.5, 2) facing east has a path east but is recovering: it drives its recovery
    (backing at ``recovery_speed``); robot2, without a path, stands. With ``halt`` every robot
    stands, a recovery under way too."""
    me = np.array([0.5, 2.0, 0.0])
    paths = {"robot1": np.array([[0.5, 2.0], [1.0, 2.0], [1.5, 2.0], [2.0, 2.0]]), "robot2": None}
    ctl = Controller(ControlConfig(recovery_speed=0.15))
    poses = {"robot1": me, "robot2": np.array([0.5, 3.5, 0.0])}
    ctl.recovery.start("robot1", me, 0.0)
    assert ctl.step(wall_south(), poses, paths, 0.2) == {"robot1": (-0.15, 0.0), "robot2": (0.0, 0.0)}
    assert ctl.step(wall_south(), poses, paths, 0.4, halt=True) == {"robot1": (0.0, 0.0), "robot2": (0.0, 0.0)}
    assert ctl.counters() == {"boxed_in": 0, "long_turns": 0, "turn_backoffs": 0, "blocked_turns": 0}


def _imports(path: Path) -> set[str]:
    """The modules ``path`` imports at run time (imports under ``if TYPE_CHECKING`` left out)."""
    tree = ast.parse(path.read_text())
    skip = {id(n) for node in ast.walk(tree) if isinstance(node, ast.If) and ast.unparse(node.test) == "TYPE_CHECKING"
            for n in ast.walk(node)}
    out = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.ImportFrom) and node.module:
            out.add(node.module)
        elif isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
    return out


@pytest.mark.parametrize(("package", "forbidden"), [("sim", ("exploration",)), ("exploration", ("sim",)),
                                                    ("control", ("sim", "exploration"))])
def test_simulation_exploration_and_control_do_not_import_each_other(package, forbidden):
    """The simulator steers its routes with the controller's pure pursuit, exploration calls the
    controller; neither imports the other, and the controller neither (types only)."""
    root = Path(__file__).resolve().parents[2] / "mrslam_core"
    for path in sorted((root / package).glob("*.py")):
        bad = {m for m in _imports(path) for f in forbidden
               if m == f"mrslam_core.{f}" or m.startswith(f"mrslam_core.{f}.")}
        assert not bad, (path.name, bad)


def test_the_platform_footprint_and_near_limit():
    """The default footprint is the simulated Pioneer's body: 0.45 × 0.38 m, its centre 0.04 m
    behind base_link, its corners hypot(0.265, 0.19) = 0.326 m from it; a footprint with no area
    and a back-off before turns that ends inside the camera's near limit are refused."""
    p = PlatformConfig()
    assert (p.length, p.width, p.centre_x) == pytest.approx((0.45, 0.38, -0.04))
    assert p.corner_radius == pytest.approx(np.hypot(0.265, 0.19))
    long_nose = PlatformConfig(front=0.5, rear=0.1, width=0.2)
    assert long_nose.corner_radius == pytest.approx(np.hypot(0.5, 0.1))
    for bad in ({"width": 0.0}, {"front": -0.3, "rear": 0.2}, {"camera_near": -0.1}):
        with pytest.raises(ValueError):
            PlatformConfig(**bad)
    with pytest.raises(ValueError, match="near limit"):
        ControlConfig(turn_clearance=0.3)  # the camera sees nothing nearer than 0.34 m
    assert ControlConfig(turn_clearance=0.3, platform=PlatformConfig(camera_near=0.3)).turn_clearance == 0.3


def test_the_simulated_body_is_the_platform_footprint():
    """The simulator builds the robot's collision box from PlatformConfig's footprint: the box
    spans x from -rear to front and y ±width/2 in base_link."""
    import xml.etree.ElementTree as ET

    from mrslam_core.sim.config import DriveConfig, StereoCameraConfig
    from mrslam_core.sim.robot import robot_description

    p = PlatformConfig()
    base = next(link for link in ET.fromstring(robot_description(StereoCameraConfig(), DriveConfig())).iter("link")
                if link.get("name") == "base_link")
    box = base.find("collision/geometry/box")
    x = float(base.find("collision/origin").get("xyz").split()[0])
    length, width, _ = (float(v) for v in box.get("size").split())
    assert (x - length / 2, x + length / 2, width) == pytest.approx((-p.rear, p.front, p.width))
