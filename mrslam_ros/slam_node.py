"""The central SLAM node: every robot's observations and odometry into ONE multi-robot filter.

Subscribes, per robot listed in the config: ``/<robot>/odom`` (nav_msgs/Odometry, odom -> base_link)
and ``/<robot>/observations`` (PointCloud2 from the frontend, base_link). Each observation set is
paired with the robot's odometry at its stamp (interpolated from the odometry it has received) and
fed to the filter as that robot's update. Publishes ``/<robot>/pose`` (PoseWithCovarianceStamped in
the map frame), ``/<robot>/path`` and map -> ``<robot>/odom`` on /tf.

Bad input is counted, never raised out of a callback: unknown frames, malformed clouds, observation
sets older than the robot's last update, and sets that arrive before any odometry.
"""

from __future__ import annotations

import sys
from collections import Counter, deque
from dataclasses import dataclass, field

import numpy as np
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry, Path
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2
from tf2_msgs.msg import TFMessage

from mrslam_core.evaluation.metrics import interpolate_poses
from mrslam_core.geometry.se2 import between, compose, inverse
from mrslam_core.slam.config import FilterConfig
from mrslam_core.slam.filter import MultiRobotFastSLAM, RobotUpdate
from mrslam_ros.conversions import (
    ConversionError,
    cloud_to_observations,
    odometry_to_pose,
    path_msg,
    pose_with_covariance,
    transform_msg,
)
from mrslam_ros.params import declare_config, read_config
from mrslam_ros.spin import run_node


@dataclass(frozen=True)
class SlamNodeConfig:
    """The central node.

    Attributes:
        robots: robot names (topic namespaces and frame prefixes).
        start_poses: known start poses, x y θ per robot in ``robots`` order (map frame).
        map_frame: name of the map frame.
        odom_buffer: odometry messages kept per robot for interpolation.
        filter: the multi-robot filter.
    """

    robots: tuple[str, ...] = ("robot1",)
    start_poses: tuple[float, ...] = (0.0, 0.0, 0.0)
    map_frame: str = "map"
    odom_buffer: int = 2000
    filter: FilterConfig = field(default_factory=FilterConfig)


class SlamNode(Node):
    """Thin wrapper: convert, call :class:`MultiRobotFastSLAM`, publish."""

    def __init__(self, name: str = "slam", **kwargs):
        super().__init__(name, **kwargs)
        declare_config(self, SlamNodeConfig())
        self.cfg = read_config(self, SlamNodeConfig)
        robots = list(self.cfg.robots)
        starts = np.asarray(self.cfg.start_poses, float).reshape(len(robots), 3)
        self.slam = MultiRobotFastSLAM(self.cfg.filter, robots, starts)
        self.drops: Counter[str] = Counter()
        self.odom: dict[str, deque] = {r: deque(maxlen=self.cfg.odom_buffer) for r in robots}
        self.last: dict[str, tuple[int, np.ndarray]] = {}  # robot -> (stamp, odom pose) of last update
        self.paths: dict[str, list[tuple[int, np.ndarray]]] = {r: [] for r in robots}
        self.pose_pub = {r: self.create_publisher(PoseWithCovarianceStamped, f"/{r}/pose", 10) for r in robots}
        self.path_pub = {r: self.create_publisher(Path, f"/{r}/path", 10) for r in robots}
        self.tf_pub = self.create_publisher(TFMessage, "/tf", 100)
        for r in robots:
            self.create_subscription(Odometry, f"/{r}/odom", lambda m, r=r: self.on_odom(r, m), 100)
            self.create_subscription(PointCloud2, f"/{r}/observations", lambda m, r=r: self.on_observations(r, m), 20)

    def on_odom(self, robot: str, msg: Odometry) -> None:
        try:
            stamp, pose, _ = odometry_to_pose(msg)
        except ConversionError:
            self.drops["bad_odometry"] += 1
            return
        buf = self.odom[robot]
        if buf and stamp <= buf[-1][0]:
            self.drops["odometry_out_of_order"] += 1
            return
        buf.append((stamp, pose))

    def odom_at(self, robot: str, stamp: int) -> np.ndarray | None:
        """Odometry pose of ``robot`` at ``stamp`` (interpolated), None outside what was received."""
        buf = self.odom[robot]
        if not buf or stamp < buf[0][0] or stamp > buf[-1][0]:
            return None
        t = np.array([s for s, _ in buf], float)
        poses = np.array([p for _, p in buf])
        return interpolate_poses(np.array([float(stamp)]), t, poses)[0]

    def on_observations(self, robot: str, msg: PointCloud2) -> None:
        if msg.header.frame_id not in (f"{robot}/base_link", "base_link"):
            self.drops["wrong_frame"] += 1
            return
        try:
            obs = cloud_to_observations(msg, robot)
        except ConversionError:
            self.drops["bad_cloud"] += 1
            return
        odom = self.odom_at(robot, obs.stamp_ns)
        if odom is None:
            self.drops["no_odometry_at_stamp"] += 1
            return
        prev = self.last.get(robot)
        if prev is not None and obs.stamp_ns <= prev[0]:
            self.drops["stale_stamp"] += 1
            return
        # the first update moves the robot from where its odometry started (at its start pose)
        reference = self.odom[robot][0][1] if prev is None else prev[1]
        delta = between(reference, odom)
        self.slam.step([RobotUpdate(robot, obs.stamp_ns, delta, obs)])
        self.last[robot] = (obs.stamp_ns, odom)
        self.publish(robot, obs.stamp_ns, odom)

    def publish(self, robot: str, stamp: int, odom: np.ndarray) -> None:
        est = self.slam.estimate()
        k = self.slam.index[robot]
        pose = est.mean[k]
        self.pose_pub[robot].publish(pose_with_covariance(pose, est.cov[k], stamp, self.cfg.map_frame))
        self.paths[robot].append((stamp, pose))
        stamps = np.array([s for s, _ in self.paths[robot]])
        self.path_pub[robot].publish(path_msg(np.array([p for _, p in self.paths[robot]]), stamps, self.cfg.map_frame))
        map_to_odom = compose(pose, inverse(odom))  # map <- odom = map <- base ⊕ base <- odom
        self.tf_pub.publish(TFMessage(transforms=[transform_msg(map_to_odom, stamp, self.cfg.map_frame, f"{robot}/odom")]))


def main(argv: list[str] | None = None) -> int:
    return run_node(SlamNode, argv)


if __name__ == "__main__":
    sys.exit(main())
