"""The view node: a Foxglove WebSocket server showing a running team, no ROS install needed on the
viewing side (open ``ws://HOST:PORT`` in the Foxglove app; config/foxglove_layout.json arranges it).

Subscribes, for each robot (``robots``, or every robot whose topics appear in the graph):
``/<robot>/{pose,path,ground_truth,goal,plan,observations}``, ``/<robot>/stereo/left/image_raw``
and ``camera_info``; and ``/tf``, ``/tf_static``, ``/map``, ``/slam/landmarks``, ``/slam/particles``,
``/exploration/frontiers`` and, with ``ellipsoids``, ``/slam/landmark_markers``. Each goes out on
the channels of :mod:`mrslam_ros.foxglove_view` in Foxglove's standard schemas.

A topic is subscribed only while a client watches a channel it feeds (checked every
``watch_period``), so an unwatched view receives nothing and costs next to nothing (docs/results.md,
"Live view", has the measurement); the ground-truth path therefore starts when a client first
watches it. Bad messages are counted, never raised; so are bad client messages (the SDK answers
them with a status). Counters go out on ``/diagnostics``.
"""

from __future__ import annotations

import re
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from geometry_msgs.msg import PoseArray, PoseStamped, PoseWithCovarianceStamped
from nav_msgs.msg import OccupancyGrid, Odometry, Path
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import MarkerArray

from mrslam_ros import foxglove_view as fv
from mrslam_ros.conversions import (
    ConversionError,
    camera_info_to_calibration,
    cloud_to_observations,
    image_to_array,
    marker_ellipsoids,
    marker_points,
    msg_to_pose,
    occupancy_to_arrays,
    odometry_to_pose,
    path_to_poses,
    pose_array_to_poses,
    stamp_to_ns,
    transform_to_arrays,
)
from mrslam_ros.diagnostics import Diagnostics
from mrslam_ros.params import declare_config, read_config
from mrslam_ros.spin import run_node

#: a robot's topics the view recognises it by (``robots`` empty)
_ROBOT_TOPIC = re.compile(r"^/([A-Za-z_][A-Za-z0-9_]*)/(pose|observations|ground_truth|stereo/left/image_raw)$")

#: best effort, volatile: a viewer that falls behind loses messages instead of holding up the
#: publisher, and it matches every publisher (reliable or not, latched or not)
_VIEW_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
_STATIC_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)


@dataclass(frozen=True)
class ViewNodeConfig:
    """The view node.

    Attributes:
        robots: robot names (their namespaces); empty: every robot whose topics appear.
        host: address the WebSocket server listens on (``0.0.0.0``: every interface).
        port: its TCP port.
        map_frame: the frame of poses, paths, landmarks and the grid.
        ellipsoids: also stream the landmarks' covariance ellipsoids (the central node then
            builds its /slam/landmark_markers, up to its ``max_markers``).
        path_spacing: ground-truth path poses are kept this far apart at least [m].
        path_period: a path (estimated, planned, ground truth) or particle cloud goes out at most
            once in this long; the estimated paths come whole with every update, and decoding
            them at the filter's rate would cost the view more than the rest together [s].
        discovery_period: how often the graph is searched for new robots (``robots`` empty) [s].
        watch_period: how often the subscriptions follow what the clients watch [s].
        static_period: how often /tf_static's transforms are sent again, for clients that
            connect later [s].
    """

    robots: tuple[str, ...] = ()
    host: str = "127.0.0.1"
    port: int = 8765
    map_frame: str = "map"
    ellipsoids: bool = False
    path_spacing: float = 0.02
    path_period: float = 1.0
    discovery_period: float = 1.0
    watch_period: float = 0.2
    static_period: float = 1.0


class ViewNode(Node):
    """Thin: deserialize what a client watches, convert, hand to :class:`fv.ViewServer`."""

    def __init__(self, name: str = "view", **kwargs):
        super().__init__(name, **kwargs)
        declare_config(self, ViewNodeConfig())
        self.cfg = read_config(self, ViewNodeConfig)
        self.server = fv.ViewServer(self.cfg.host, self.cfg.port)
        self.get_logger().info(f"Foxglove WebSocket server on ws://{self.cfg.host}:{self.server.port}")
        self.diag = Diagnostics(self)
        self.robots: set[str] = set()
        self.truth_path: dict[str, list[tuple[int, np.ndarray]]] = {}
        self._truth_sent: dict[str, float] = {}  # per robot, when its ground-truth path went out [s, monotonic]
        self.camera_info: dict[str, CameraInfo] = {}
        #: /tf_static: child frame -> (stamp [ns], parent, child, translation (3,), quaternion (4,))
        self.statics: dict[str, tuple] = {}
        #: per ROS topic: (message type, channels that need it, callback on the serialized bytes, QoS)
        self.feeds: dict[str, tuple[type, tuple[str, ...], Callable[[bytes], None], QoSProfile]] = {}
        #: the subscriptions made now, by topic: only while a client watches a channel they feed
        self.subs: dict[str, object] = {}
        frame = self.cfg.map_frame
        self._feed(TFMessage, "/tf", ("/tf",), self.on_tf)
        self.create_subscription(TFMessage, "/tf_static", self.on_tf_static, _STATIC_QOS, raw=True)
        self._feed(OccupancyGrid, "/map", ("/map",),
                   lambda m: fv.occupancy_grid(*occupancy_to_arrays(m), stamp_to_ns(m.header.stamp), frame), send=True)
        self._feed(PointCloud2, "/slam/landmarks", ("/slam/landmarks",),
                   lambda m: fv.point_cloud(cloud_to_observations(m, "map").z, stamp_to_ns(m.header.stamp), frame), send=True)
        self._feed(PoseArray, "/slam/particles", ("/slam/particles",),
                   lambda m: fv.poses_in_frame(pose_array_to_poses(m), stamp_to_ns(m.header.stamp), frame), send=True,
                   every=self.cfg.path_period)
        self._feed(MarkerArray, "/exploration/frontiers", ("/exploration/frontiers",), self._frontiers)
        if self.cfg.ellipsoids:
            self._feed(MarkerArray, "/slam/landmark_markers", ("/slam/landmark_ellipsoids",), self._ellipsoids)
        for robot in self.cfg.robots:
            self.add_robot(robot)
        steady = Clock(clock_type=ClockType.STEADY_TIME)  # before /clock starts, too
        if not self.cfg.robots:
            self.create_timer(self.cfg.discovery_period, self.discover, clock=steady)
        self.create_timer(self.cfg.watch_period, self.follow_clients, clock=steady)
        self.create_timer(self.cfg.static_period, self.send_statics, clock=steady)
        self.create_timer(1.0, self.report, clock=steady)

    # ------------------------------------------------------------------ plumbing
    def _feed(self, msg_type, topic: str, channels: tuple[str, ...], convert: Callable, send: bool = False,
              every: float = 0.0) -> None:
        """Register ``topic``: while a client watches one of ``channels``, its messages are
        deserialized and passed to ``convert``, at most one in ``every`` seconds (the others are
        skipped undecoded); with ``send`` what that returns goes out on ``channels[0]`` stamped
        like the message (otherwise ``convert`` sends what it makes)."""
        last = [-np.inf]

        def callback(data: bytes) -> None:
            now = time.monotonic()
            if now - last[0] < every:
                return
            last[0] = now
            try:
                msg = deserialize_message(data, msg_type)
                out = convert(msg)
                if send:
                    self.server.log(channels[0], out, stamp_to_ns(msg.header.stamp))
            except (ConversionError, ValueError, TypeError) as exc:
                self.diag.count(f"bad_{topic.strip('/').replace('/', '_')}", str(exc))

        for ch in channels:
            self.server.advertise(ch)
        self.feeds[topic] = (msg_type, channels, callback, _VIEW_QOS)

    def follow_clients(self) -> None:
        """Subscribe the topics whose channels a client watches now; drop the others' subscriptions.
        The middleware then delivers nothing to an unwatched view."""
        for topic, (msg_type, channels, callback, qos) in self.feeds.items():
            wanted = any(self.server.wants(ch) for ch in channels)
            if wanted and topic not in self.subs:
                self.subs[topic] = self.create_subscription(msg_type, topic, callback, qos, raw=True)
            elif not wanted and topic in self.subs:
                self.destroy_subscription(self.subs.pop(topic))

    def add_robot(self, robot: str) -> None:
        """Register ``robot``'s topics and advertise its channels."""
        if robot in self.robots:
            return
        self.robots.add(robot)
        frame, ns = self.cfg.map_frame, f"/{robot}"
        self.truth_path[robot] = []
        # a robot not joined yet sends its pose, goal and plan in its own start frame: kept in it,
        # not drawn in the map where they are not
        self._feed(PoseWithCovarianceStamped, f"{ns}/pose", (f"{ns}/pose",),
                   lambda m: fv.pose_in_frame(msg_to_pose(m.pose.pose), stamp_to_ns(m.header.stamp),
                                              m.header.frame_id or frame), send=True)
        self._feed(Path, f"{ns}/path", (f"{ns}/path",),
                   lambda m: fv.poses_in_frame(path_to_poses(m)[0], stamp_to_ns(m.header.stamp), frame), send=True,
                   every=self.cfg.path_period)
        self._feed(PoseStamped, f"{ns}/goal", (f"{ns}/goal",),
                   lambda m: fv.pose_in_frame(msg_to_pose(m.pose), stamp_to_ns(m.header.stamp), m.header.frame_id or frame),
                   send=True)
        self._feed(Path, f"{ns}/plan", (f"{ns}/plan",),
                   lambda m: fv.poses_in_frame(path_to_poses(m)[0], stamp_to_ns(m.header.stamp), m.header.frame_id or frame),
                   send=True, every=self.cfg.path_period)
        camera = (f"{ns}/image", f"{ns}/image_points", f"{ns}/camera_calibration")
        self._feed(Image, f"{ns}/stereo/left/image_raw", camera[::2], lambda m, r=robot: self._image(r, m))
        self._feed(PointCloud2, f"{ns}/observations", camera[1:2], lambda m, r=robot: self._image_points(r, m))
        self._feed(CameraInfo, f"{ns}/stereo/left/camera_info", camera, lambda m, r=robot: self.camera_info.__setitem__(r, m))
        self._feed(Odometry, f"{ns}/ground_truth", (f"{ns}/ground_truth", f"{ns}/ground_truth_path"),
                   lambda m, r=robot: self._truth(r, m))
        self.get_logger().info(f"viewing {robot}")

    def discover(self) -> None:
        for topic, _ in self.get_topic_names_and_types():
            m = _ROBOT_TOPIC.match(topic)
            if m:
                self.add_robot(m.group(1))

    # ------------------------------------------------------------------ streams
    def on_tf(self, msg: TFMessage) -> None:
        if msg.transforms:
            items = [transform_to_arrays(t) for t in msg.transforms]
            self.server.log("/tf", fv.frame_transforms(items), max(i[0] for i in items))

    def on_tf_static(self, data: bytes) -> None:
        try:
            for t in deserialize_message(data, TFMessage).transforms:
                item = transform_to_arrays(t)
                self.statics[item[2]] = item
        except (ConversionError, ValueError, TypeError) as exc:
            self.diag.count("bad_tf_static", str(exc))
        self.send_statics()

    def send_statics(self) -> None:
        if self.statics and self.server.wants("/tf"):
            items = list(self.statics.values())
            self.server.log("/tf", fv.frame_transforms(items), max(i[0] for i in items))

    def _frontiers(self, msg: MarkerArray):
        stamp = stamp_to_ns(msg.markers[0].header.stamp) if msg.markers else 0
        size = float(msg.markers[0].scale.x) if msg.markers else 0.25
        self.server.log("/exploration/frontiers", fv.spheres(marker_points(msg), size, stamp, self.cfg.map_frame), stamp)

    def _ellipsoids(self, msg: MarkerArray):
        stamps = [stamp_to_ns(m.header.stamp) for m in msg.markers]
        stamp = max(stamps) if stamps else 0
        self.server.log("/slam/landmark_ellipsoids", fv.ellipsoids(*marker_ellipsoids(msg), stamp, self.cfg.map_frame), stamp)

    def _image(self, robot: str, msg: Image) -> None:
        stamp = stamp_to_ns(msg.header.stamp)
        channel = f"/{robot}/camera_calibration"
        info = self.camera_info.get(robot)
        if info is not None and self.server.wants(channel):
            cal = camera_info_to_calibration(info)
            self.server.log(channel, fv.camera_calibration(cal.K, cal.D, cal.R, cal.P, cal.width, cal.height,
                                                           cal.distortion_model, stamp, msg.header.frame_id), stamp)
        if self.server.wants(f"/{robot}/image"):
            self.server.log(f"/{robot}/image", fv.raw_image(image_to_array(msg), msg.encoding, stamp, msg.header.frame_id), stamp)

    def _image_points(self, robot: str, msg: PointCloud2) -> None:
        """The observed points on the image: base_link -> the left camera's frame (its mount from
        /tf_static, as the simulator and dataset bags publish it) -> pixels."""
        info = self.camera_info.get(robot)
        if info is None:
            return
        mount = fv.chain({c: (p, t, q) for _, p, c, t, q in self.statics.values()}, f"{robot}/base_link",
                         info.header.frame_id)
        if mount is None:
            self.diag.count("no_camera_mount", f"/tf_static has no {robot}/base_link -> {info.header.frame_id}")
            return
        cal = camera_info_to_calibration(info)
        obs = cloud_to_observations(msg, robot)
        uv = fv.project_points(obs.z, mount, cal.K, cal.D, cal.width, cal.height)
        self.server.log(f"/{robot}/image_points", fv.image_points(uv, obs.stamp_ns), obs.stamp_ns)

    def _truth(self, robot: str, msg: Odometry) -> None:
        stamp, pose, _ = odometry_to_pose(msg)
        path = self.truth_path[robot]
        if not path or np.hypot(*(pose[:2] - path[-1][1][:2])) >= self.cfg.path_spacing:
            path.append((stamp, pose))
        frame = self.cfg.map_frame
        if self.server.wants(f"/{robot}/ground_truth"):
            self.server.log(f"/{robot}/ground_truth", fv.pose_in_frame(pose, stamp, frame), stamp)
        channel = f"/{robot}/ground_truth_path"
        now = time.monotonic()
        if self.server.wants(channel) and now - self._truth_sent.get(robot, -np.inf) >= self.cfg.path_period:
            self._truth_sent[robot] = now
            self.server.log(channel, fv.poses_in_frame(np.array([p for _, p in path]), stamp, frame), stamp)

    def report(self) -> None:
        self.diag.mirror(self.server.client_errors, "client_", "bad client messages (ignored)")
        self.diag.set("subscriptions", float(self.server.subscriptions))
        self.diag.set("robots", float(len(self.robots)))
        self.diag.set("sent", float(sum(self.server.sent.values())))

    def destroy_node(self) -> None:
        try:
            self.server.close()
        finally:
            super().destroy_node()


def main(argv: list[str] | None = None) -> int:
    """``python -m mrslam_ros.view_node --ros-args -p robots:=[robot1] -p port:=8765``."""
    return run_node(ViewNode, argv)


if __name__ == "__main__":
    sys.exit(main())
