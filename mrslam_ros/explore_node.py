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

A robot whose start pose is unknown (the SLAM node's ``unknown_start``) has poses in its own start
frame (``<robot>/start``) until it joins the map. It explores alone there, on a grid of its own
(:class:`~mrslam_core.exploration.own_frame.OwnFrameExploration`; its goal and plan go out in that
frame). When ``/<robot>/start_pose`` (latched: its start frame in the map) comes, its scans are
moved into the team's grid and it explores with the team.
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
from mrslam_core.exploration.own_frame import OwnFrameExploration
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
    start_frame,
)
from mrslam_ros.diagnostics import Diagnostics
from mrslam_ros.params import declare_config, read_config
from mrslam_ros.qos import qos_for_topic
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
        self.poses: dict[str, np.ndarray] = {}  # map frame
        self.pose_stamps: dict[str, int] = {}
        #: robots not in the map frame (yet): their own exploration, and their poses in their start frame
        self.own: dict[str, OwnFrameExploration] = {}
        self.own_poses: dict[str, np.ndarray] = {}
        self.joined_ns: dict[str, int] = {}  # stamp of each robot's latest join
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
            self.create_subscription(PoseStamped, f"/{r}/start_pose", lambda m, r=r: self.on_start_pose(r, m),
                                     qos_for_topic(f"/{r}/start_pose"))
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
        stamp, frame = stamp_to_ns(msg.header.stamp), msg.header.frame_id
        if frame == self.cfg.map_frame:
            self.poses[robot] = pose
        elif frame == start_frame(robot):
            if stamp <= self.joined_ns.get(robot, -1):
                return  # from before its join, come late
            if robot not in self.own:
                self._explore_alone(robot)
            self.own_poses[robot] = pose
        else:
            self.diag.count("pose_frame", f"{robot}: a pose in {frame!r}, neither {self.cfg.map_frame!r} nor "
                            f"{start_frame(robot)!r}")
            return
        self.pose_stamps[robot] = stamp
        self.now_ns = max(self.now_ns, stamp)
        self._pair(robot, 0, stamp, (frame, pose))

    def _explore_alone(self, robot: str) -> None:
        """``robot`` is not in the map frame: it explores its own grid until it joins."""
        self.own[robot] = OwnFrameExploration.create(robot, self.cfg.exploration, self.cfg.grid,
                                                     self.explorer.controller)
        if robot in self.explorer.robots:  # an odometry reset: mapped on its own again
            self.explorer.robots.remove(robot)
            self.explorer.goals.pop(robot, None)
        self.poses.pop(robot, None)
        self.get_logger().info(f"{robot} has no map pose: it explores alone in {start_frame(robot)} until it joins")

    def on_start_pose(self, robot: str, msg: PoseStamped) -> None:
        """``robot`` joined the map with its start frame at ``msg``'s pose: its scans go into the
        team's grid, and it explores with the team."""
        transform = msg_to_pose(msg.pose)
        if msg.header.frame_id != self.cfg.map_frame or not np.isfinite(transform).all():
            self.diag.count("bad_start_pose", f"{robot}: a start pose not finite or not in {self.cfg.map_frame!r}")
            return
        self.joined_ns[robot] = stamp_to_ns(msg.header.stamp)
        own = self.own.pop(robot, None)
        self.own_poses.pop(robot, None)
        if own is not None:
            n = own.hand_over(self.grid, transform)
            self.get_logger().info(f"{robot} joined the map: its {n} scans moved into the team's grid")
        if robot not in self.explorer.robots:
            self.explorer.robots.append(robot)

    def on_scan(self, robot: str, msg: LaserScan) -> None:
        self.scans_received += 1
        self._pair(robot, 1, stamp_to_ns(msg.header.stamp), msg)

    def on_bumper(self, robot: str, msg: PointCloud2) -> None:
        """What the robot's bumper touches (base_link points) is an obstacle in the grid, placed
        with its newest pose; pressed ahead of it, its goal fails (``Explorer.bumped``)."""
        own = self.own.get(robot)
        if robot not in (self.own_poses if own else self.poses):
            self.diag.count("bumper_without_pose", f"{robot}: a bumper contact before its first pose")
            return
        try:
            points = cloud_to_contacts(msg)
        except ConversionError as exc:
            self.diag.count("bad_bumper", f"{robot}: {exc}")
            return
        explorer, grid, poses = ((own.explorer, own.grid, self.own_poses) if own
                                 else (self.explorer, self.grid, self.poses))
        if explorer.bumped(grid, robot, points, poses, self.now_ns * 1e-9):
            self.get_logger().warning(f"{robot}'s bumper is pressed ahead of it: goal given up, backing off; "
                                      f"{explorer.bumped_goals} such goals so far")

    def _pair(self, robot: str, stream: int, stamp_ns: int, item) -> None:
        """Offer a pose (stream 0) or a scan (stream 1); a pose and a scan of one stamp go into the grid."""
        pair = self.scan_sync[robot].add(stream, stamp_ns, item)
        if pair is not None:
            (frame, pose), scan = pair[0], laser_to_scan(pair[1])
            others = [p[:2] for r, p in self.poses.items() if r != robot and r not in self.own]
            if frame == self.cfg.map_frame:
                self.grid.insert(pose, scan, others)
            elif robot in self.own:
                self.own[robot].insert(pose, scan, np.array(others).reshape(-1, 2))
            else:  # its start frame, paired after its join: the pose is in the team's grid already
                return
            self.scans_inserted += 1
        # dropped by the synchroniser (overflow, unmatched, late, duplicate) = neither laid nor waiting
        waiting = sum(s.queued()[1] for s in self.scan_sync.values())
        self.diag.mirror({"scan_without_pose": self.scans_received - self.scans_inserted - waiting}, "",
                         "a scan whose pose never came (its set dropped by the central node)")

    def control(self) -> None:
        if any(r not in (self.own_poses if r in self.own else self.poses) for r in self.cfg.robots):
            return  # every robot must have a pose before targets are shared out
        before = self.explorer.controller.counters()
        now = self.now_ns * 1e-9
        commands = self.explorer.step(self.grid, {r: self.poses[r] for r in self.explorer.robots}, now)
        for r, own in self.own.items():
            commands |= own.explorer.step(own.grid, {r: self.own_poses[r]}, now)
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
            own = self.own.get(robot)
            goal = (own.explorer if own else self.explorer).goals.get(robot)
            frame = start_frame(robot) if own else self.cfg.map_frame
            if goal is not None:
                self.goal_pub[robot].publish(pose_stamped_msg(np.array([goal.target[0], goal.target[1], 0.0]),
                                                              clock_ns, frame))
            if goal is not self._planned.get(robot):
                self._planned[robot] = goal
                path = np.zeros((0, 2)) if goal is None else np.asarray(goal.path, float).reshape(-1, 2)
                poses = np.column_stack([path, np.zeros(len(path))])
                self.plan_pub[robot].publish(path_msg(poses, np.full(len(path), self.now_ns), frame))

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
