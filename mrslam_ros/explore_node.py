"""The central exploration node: one occupancy grid for the team, coordinated frontier goals,
and each robot's drive command (the controller, path follower and recovery, runs here, per robot).

Subscribes ``/<robot>/scan`` (LaserScan in base_link from the frontend), ``/<robot>/pose``
(PoseWithCovarianceStamped in the map frame from the SLAM node) and ``/<robot>/bumper``
(PointCloud2 of contact points in base_link, from a robot with a bumper: each an obstacle for
good at the robot's newest pose, as a stereo camera does not see a wall without texture; pressed
ahead of the robot, its goal is given up and it backs off). Each scan is inserted at its
robot's pose of the same stamp (the frontend stamps a scan and its observation set with the image
pair's stamp, and the SLAM node stamps the pose of that set with it): the latest pose is a frame
or two older than a new scan, and a robot turning at 0.5 rad/s would lay its scans 3-6° off,
eroding the walls at door frames that the planner then cuts through. A scan whose pose never
comes (its set dropped by the SLAM node) is counted, not inserted; drops and stops go out on
``/diagnostics``. Publishes ``/map``
(OccupancyGrid; the grid grows with the scans, and info.origin, width and height with it) and
``/exploration/frontiers`` (MarkerArray: one sphere per candidate target of the last plan) on
one timer, ``/<robot>/cmd_vel``, ``/<robot>/goal`` (PoseStamped) and ``/<robot>/plan`` (Path, the
A* path to the goal, when it changes) on another.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field

import numpy as np
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped, Twist
from nav_msgs.msg import OccupancyGrid, Path
from rclpy.node import Node
from sensor_msgs.msg import LaserScan, PointCloud2
from visualization_msgs.msg import MarkerArray

from mrslam_core.control.config import ControlConfig
from mrslam_core.control.controller import Controller
from mrslam_core.exploration.config import ExplorationConfig, GridConfig
from mrslam_core.exploration.explorer import Explorer
from mrslam_core.exploration.grid import OccupancyGrid as Grid
from mrslam_ros.conversions import (
    ConversionError,
    cloud_to_contacts,
    laser_to_scan,
    msg_to_pose,
    occupancy_msg,
    path_msg,
    points_marker,
    pose_stamped_msg,
    stamp_to_ns,
)
from mrslam_ros.diagnostics import Diagnostics
from mrslam_ros.params import declare_config, read_config
from mrslam_ros.spin import run_node
from mrslam_ros.sync import ApproximateTimeSync


@dataclass(frozen=True)
class ExploreNodeConfig:
    """The exploration node.

    Attributes:
        robots: robot names.
        control_period: command period [s].
        map_period: /map publication period [s].
        map_frame: frame of the grid and the poses.
        pose_timeout: a robot whose latest pose is older than this is stopped until a new pose
            comes (the central node is down, or the robot's observations stopped) [s].
        scan_queue: scans (and poses) held per robot while waiting for the pose (scan) of the
            same stamp.
    """

    robots: tuple[str, ...] = ("robot1",)
    control_period: float = 0.2
    map_period: float = 2.0
    map_frame: str = "map"
    pose_timeout: float = 2.0
    scan_queue: int = 10
    exploration: ExplorationConfig = field(default_factory=ExplorationConfig)
    control: ControlConfig = field(default_factory=ControlConfig)
    grid: GridConfig = field(default_factory=GridConfig)


#: the controller's counters (Controller.counters) the node logs as they grow: (name, as a warning, what happened)
EVENTS = (
    ("boxed_in", True, "a robot can reach no frontier from where it stands: recovering; times"),
    ("long_turns", False, "a robot turns the long way round, away from a wall (open_side_turns); such turns"),
    ("turn_backoffs", False, "a robot backs away from a wall before turning on the spot (turn_clearance); such turns"),
    ("blocked_turns", True, "a robot's turn on the spot did not turn (against a jamb or a teammate): turning the "
                            "other way round (turn_stall_time); such turns"),
)


class ExploreNode(Node):
    """Thin wrapper around :class:`Explorer` and the grid."""

    def __init__(self, name: str = "explore", **kwargs):
        super().__init__(name, **kwargs)
        declare_config(self, ExploreNodeConfig())
        self.cfg = read_config(self, ExploreNodeConfig)
        self.grid = Grid(self.cfg.grid)
        self.explorer = Explorer(self.cfg.exploration, list(self.cfg.robots), Controller(self.cfg.control))
        self.poses: dict[str, np.ndarray] = {}
        self.pose_stamps: dict[str, int] = {}
        self.diag = Diagnostics(self)
        #: per robot: its poses (stream 0) and scans (stream 1) paired by exact stamp
        self.scan_sync = {r: ApproximateTimeSync(2, 0, self.cfg.scan_queue) for r in self.cfg.robots}
        self.scans_received = self.scans_inserted = 0
        self.cmd_pub = {r: self.create_publisher(Twist, f"/{r}/cmd_vel", 10) for r in self.cfg.robots}
        self.goal_pub = {r: self.create_publisher(PoseStamped, f"/{r}/goal", 10) for r in self.cfg.robots}
        self.plan_pub = {r: self.create_publisher(Path, f"/{r}/plan", 10) for r in self.cfg.robots}
        self.map_pub = self.create_publisher(OccupancyGrid, "/map", 1)
        self.frontier_pub = self.create_publisher(MarkerArray, "/exploration/frontiers", 1)
        self._planned: dict[str, object] = {}  # per robot, the goal whose plan went out last
        for r in self.cfg.robots:
            self.create_subscription(PoseWithCovarianceStamped, f"/{r}/pose", lambda m, r=r: self.on_pose(r, m), 10)
            self.create_subscription(LaserScan, f"/{r}/scan", lambda m, r=r: self.on_scan(r, m), 10)
            self.create_subscription(PointCloud2, f"/{r}/bumper", lambda m, r=r: self.on_bumper(r, m), 10)
        self.create_timer(self.cfg.control_period, self.control)
        self.create_timer(self.cfg.map_period, self.publish_map)
        self.now_ns = 0

    @property
    def drops(self):
        """Dropped inputs and stops by reason (also on /diagnostics)."""
        return self.diag.drops

    def on_pose(self, robot: str, msg: PoseWithCovarianceStamped) -> None:
        pose = msg_to_pose(msg.pose.pose)
        if not np.isfinite(pose).all():
            self.diag.count("bad_pose", "a pose that is not finite")
            return
        self.poses[robot] = pose
        self.pose_stamps[robot] = stamp_to_ns(msg.header.stamp)
        self.now_ns = max(self.now_ns, self.pose_stamps[robot])
        self._pair(robot, 0, self.pose_stamps[robot], pose)

    def on_scan(self, robot: str, msg: LaserScan) -> None:
        self.scans_received += 1
        self._pair(robot, 1, stamp_to_ns(msg.header.stamp), msg)

    def on_bumper(self, robot: str, msg: PointCloud2) -> None:
        """What the robot's bumper touches (base_link points) is an obstacle in the grid, placed
        with its newest pose; pressed ahead of it, its goal fails (``Explorer.bumped``)."""
        if robot not in self.poses:
            self.diag.count("bumper_without_pose", f"{robot}: a bumper contact before its first pose")
            return
        try:
            points = cloud_to_contacts(msg)
        except ConversionError as exc:
            self.diag.count("bad_bumper", f"{robot}: {exc}")
            return
        if self.explorer.bumped(self.grid, robot, points, self.poses, self.now_ns * 1e-9):
            self.get_logger().warning(f"{robot}'s bumper is pressed ahead of it: goal given up, backing off; "
                                      f"{self.explorer.bumped_goals} such goals so far")

    def _pair(self, robot: str, stream: int, stamp_ns: int, item) -> None:
        """Offer a pose (stream 0) or a scan (stream 1); a pose and a scan of one stamp go into the grid."""
        pair = self.scan_sync[robot].add(stream, stamp_ns, item)
        if pair is not None:
            others = [p[:2] for r, p in self.poses.items() if r != robot]
            self.grid.insert(pair[0], laser_to_scan(pair[1]), others)
            self.scans_inserted += 1
        # dropped by the synchroniser (overflow, unmatched, late, duplicate) = neither laid nor waiting
        waiting = sum(s.queued()[1] for s in self.scan_sync.values())
        self.diag.mirror({"scan_without_pose": self.scans_received - self.scans_inserted - waiting}, "",
                         "a scan whose pose never came (its set dropped by the central node)")

    def control(self) -> None:
        if len(self.poses) < len(self.cfg.robots):
            return  # every robot must have a pose before targets are shared out
        before = self.explorer.controller.counters()
        commands = self.explorer.step(self.grid, self.poses, self.now_ns * 1e-9)
        after = self.explorer.controller.counters()
        for name, warn, what in EVENTS:
            if after[name] > before[name]:
                msg = f"{what}: {after[name]} so far"
                # one call site per severity: rclpy refuses a site whose severity changes
                if warn:
                    self.get_logger().warning(msg)
                else:
                    self.get_logger().info(msg)
        clock_ns = self.get_clock().now().nanoseconds
        for robot, (v, w) in commands.items():
            if clock_ns - self.pose_stamps[robot] > self.cfg.pose_timeout * 1e9:
                v = w = 0.0  # no fresh estimate: stand still rather than drive blind
                self.diag.count("stale_pose", f"{robot}: no pose for {(clock_ns - self.pose_stamps[robot]) * 1e-9:.1f} s; "
                                "stopped")
            twist = Twist()
            twist.linear.x, twist.angular.z = float(v), float(w)
            self.cmd_pub[robot].publish(twist)
            goal = self.explorer.goals.get(robot)
            if goal is not None:
                self.goal_pub[robot].publish(pose_stamped_msg(np.array([goal.target[0], goal.target[1], 0.0]),
                                                              clock_ns, self.cfg.map_frame))
            if goal is not self._planned.get(robot):
                self._planned[robot] = goal
                path = np.zeros((0, 2)) if goal is None else np.asarray(goal.path, float).reshape(-1, 2)
                poses = np.column_stack([path, np.zeros(len(path))])
                self.plan_pub[robot].publish(path_msg(poses, np.full(len(path), self.now_ns), self.cfg.map_frame))

    def publish_map(self) -> None:
        """The grid as it is now: its size and origin follow its growth; nothing before the first scan."""
        if not self.grid.observed.size:
            return
        self.map_pub.publish(occupancy_msg(self.grid.probability(), self.grid.observed, self.grid.origin,
                                           self.grid.res, self.now_ns, self.cfg.map_frame))
        self.frontier_pub.publish(points_marker(self.explorer.frontiers, self.now_ns, self.cfg.map_frame, "frontiers"))


def main(argv: list[str] | None = None) -> int:
    return run_node(ExploreNode, argv)


if __name__ == "__main__":
    sys.exit(main())
