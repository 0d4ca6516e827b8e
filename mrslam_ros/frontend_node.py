"""The per-robot stereo frontend node (run it in the robot's namespace).

Subscribes ``stereo/{left,right}/image_raw`` and ``stereo/{left,right}/camera_info``, pairs left and
right images whose stamps differ by at most ``max_skew_ns`` (approximate-time sync of
:mod:`mrslam_ros.sync`, since message_filters is not on PyPI) with the latest camera_info of each
side, runs :class:`mrslam_core.frontend.frontend.Frontend`, and publishes
``observations`` (PointCloud2 in ``<robot>/base_link``), ``sightings`` (one nav_msgs/Odometry per
other robot whose tag the frame showed, ``FrontendConfig.fiducials``: that robot's position in
``<robot>/base_link``, published before the frame's observations), ``scan`` (the pseudo laser scan for the
occupancy grid, LaserScan in ``<robot>/base_link``) and ``visual_odom`` (nav_msgs/Odometry of
base_link in ``<robot>/visual_odom``, base_link at the first frame: the frontend's visual odometry,
with the planar pose covariance and the body twist's covariance; frames whose motion could not be
estimated are counted as ``vo_failures``). Where the robot publishes wheel odometry (``odom``), its
motion between two frames places the tracks' search windows; otherwise the visual odometry's own
constant-velocity prediction does. A frame without usable points still gives an
(empty) observation set, so the central node knows the robot is alive. Drops are counted and
published on ``/diagnostics``, never raised: missing or bad camera_info, unpaired, late or
duplicated images, wrong encodings or sizes, and whatever the frontend itself rejects.
"""

from __future__ import annotations

import sys
from collections import deque
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image, LaserScan, PointCloud2

from mrslam_core.frontend.camera import StereoRig
from mrslam_core.frontend.config import FiducialConfig, FrontendConfig
from mrslam_core.frontend.errors import FrontendError
from mrslam_core.geometry.se2 import between, planar_from_matrix
from mrslam_ros.conversions import (
    ConversionError,
    camera_info_to_calibration,
    image_to_array,
    obstacle_scan_to_laser,
    observations_to_cloud,
    odometry_to_pose,
    sighting_to_msg,
    stamp_to_ns,
    visual_odometry_msg,
)
from mrslam_ros.diagnostics import Diagnostics, incompatible_qos_events
from mrslam_ros.params import declare_config, read_config
from mrslam_ros.qos import OBSERVATION_HISTORY, ODOMETRY_HISTORY
from mrslam_ros.spin import run_node
from mrslam_ros.sync import ApproximateTimeSync

_SIM_EXTRINSIC = (0.0, 0.0, 1.0, 0.12, -1.0, 0.0, 0.0, 0.06, 0.0, -1.0, 0.0, 0.45, 0.0, 0.0, 0.0, 1.0)


@dataclass(frozen=True)
class FrontendNodeConfig:
    """The frontend node.

    Attributes:
        robot: robot name (frame prefix, name in the observation sets).
        t_base_cam: row-major 4×4 base_link <- left camera optical frame (default: the simulator's
            Pioneer head: 0.12 m ahead, 0.06 m left, 0.45 m up).
        max_skew_ns: largest left/right stamp difference paired [ns].
        queue: images kept per side while waiting for a partner.
        image_qos: reliability of the image and camera_info subscriptions: ``reliable`` matches
            reliable publishers only (the simulator, bag replays); ``best_effort`` matches both,
            and is what a camera driver publishing best-effort (ROS's sensor-data QoS) needs. A
            publisher the subscription cannot match is counted as ``incompatible_qos``.
        frontend: the frontend's own parameters.
        fiducials: the robots' tags, reported on ``sightings``.
    """

    robot: str = "robot1"
    t_base_cam: tuple[float, ...] = _SIM_EXTRINSIC
    max_skew_ns: int = 5_000_000
    queue: int = 5
    image_qos: Literal["reliable", "best_effort"] = "reliable"
    frontend: FrontendConfig = field(default_factory=FrontendConfig)
    fiducials: FiducialConfig = field(default_factory=FiducialConfig)


class FrontendNode(Node):
    """Thin wrapper around the frontend core."""

    def __init__(self, name: str = "frontend", **kwargs):
        super().__init__(name, **kwargs)
        declare_config(self, FrontendNodeConfig())
        self.cfg = read_config(self, FrontendNodeConfig)
        self.diag = Diagnostics(self)
        self.infos: dict[str, CameraInfo] = {}
        self.sync = ApproximateTimeSync(2, self.cfg.max_skew_ns, self.cfg.queue)
        self.frontend = None
        self._rig_key = None
        self.pub = self.create_publisher(PointCloud2, "observations", OBSERVATION_HISTORY)
        self.sighting_pub = self.create_publisher(Odometry, "sightings", OBSERVATION_HISTORY)
        self.scan_pub = self.create_publisher(LaserScan, "scan", 10)
        # kept transient-local like wheel odometry: a central node that starts late still takes
        # the robot's start from its first pose
        self.vo_pub = self.create_publisher(Odometry, "visual_odom", ODOMETRY_HISTORY)
        # the robot's wheel odometry, when it has one, predicts the tracks' search windows
        self._odom: deque[tuple[int, np.ndarray]] = deque(maxlen=500)
        self._odom_at_frame: np.ndarray | None = None
        #: frames of a robot with wheel odometry that went without its prior, by cause: the
        #: odometry at the frame's stamp had not arrived yet (``behind``), or the previous frame
        #: had none (``previous``); reported on /diagnostics as ``prior_missing_*``
        self.prior_missing = {"behind": 0, "previous": 0}
        self.create_subscription(Odometry, "odom", self.on_odom, 50, event_callbacks=incompatible_qos_events(self.diag, "odom"))
        self._vo_cov = np.zeros((3, 3))  # the planar pose covariance of the visual odometry
        self._vo_stamp: int | None = None
        sensor_qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT if self.cfg.image_qos == "best_effort"
                                else ReliabilityPolicy.RELIABLE)
        for i, side in enumerate(("left", "right")):
            info, image = f"stereo/{side}/camera_info", f"stereo/{side}/image_raw"
            self.create_subscription(CameraInfo, info, lambda m, s=side: self.infos.__setitem__(s, m), sensor_qos,
                                     event_callbacks=incompatible_qos_events(self.diag, info))
            self.create_subscription(Image, image, lambda m, i=i: self.on_image(i, m), sensor_qos,
                                     event_callbacks=incompatible_qos_events(self.diag, image))

    @property
    def drops(self):
        """Drops by reason (this node's and the synchroniser's)."""
        return self.diag.drops

    def _ensure_frontend(self) -> bool:
        if "left" not in self.infos or "right" not in self.infos:
            self.diag.count("no_camera_info", "no camera_info received yet for both cameras")
            return False
        key = (tuple(self.infos["left"].p), tuple(self.infos["right"].p), tuple(self.infos["left"].d))
        if key != self._rig_key:
            try:
                rig = StereoRig(camera_info_to_calibration(self.infos["left"]), camera_info_to_calibration(self.infos["right"]),
                                np.asarray(self.cfg.t_base_cam, float).reshape(4, 4))
            except (ConversionError, FrontendError, ValueError) as exc:
                self.diag.count("bad_camera_info", str(exc))
                return False
            from mrslam_core.frontend.frontend import Frontend

            self.frontend = Frontend(rig, self.cfg.frontend, robot=self.cfg.robot, fiducials=self.cfg.fiducials)
            self._rig_key = key
        return True

    def on_odom(self, msg: Odometry) -> None:
        try:
            stamp, pose, _ = odometry_to_pose(msg)
        except ConversionError as exc:
            self.diag.count("bad_odometry", str(exc))
            return
        if not self._odom or stamp > self._odom[-1][0]:
            self._odom.append((stamp, pose))

    def _wheel_motion(self, stamp_ns: int) -> np.ndarray | None:
        """The wheel odometry's base_link motion (4, 4) since the previous frame, or None when the
        odometry does not reach both frames' stamps."""
        from mrslam_core.evaluation.metrics import interpolate_poses
        from mrslam_core.frontend.odometry import planar_motion

        pose = None
        if len(self._odom) >= 2 and self._odom[0][0] <= stamp_ns <= self._odom[-1][0]:
            t = np.array([s for s, _ in self._odom], float)
            pose = interpolate_poses(np.array([float(stamp_ns)]), t, np.array([p for _, p in self._odom]))[0]
        last, self._odom_at_frame = self._odom_at_frame, pose
        cause = None
        if self._odom and pose is None and stamp_ns > self._odom[-1][0]:
            cause = "behind"
        elif self._odom and pose is not None and last is None:
            cause = "previous"
        if cause is not None:
            self.prior_missing[cause] += 1
            self.diag.set(f"prior_missing_{cause}", self.prior_missing[cause])
        if pose is None or last is None:
            return None
        return planar_motion(between(last, pose))

    def on_image(self, side: int, msg: Image) -> None:
        pair = self.sync.add(side, stamp_to_ns(msg.header.stamp), msg)
        self.diag.mirror(self.sync.drops, "images_", "left/right images not paired")
        if pair is not None:
            self.process(*pair)

    def process(self, left: Image, right: Image) -> None:
        if not self._ensure_frontend():
            return
        try:
            l_img, r_img = image_to_array(left), image_to_array(right)
        except ConversionError as exc:
            self.diag.count("bad_image", str(exc))
            return
        stamp = stamp_to_ns(left.header.stamp)
        obs, scan = self.frontend.step(l_img, r_img, stamp, right_stamp_ns=stamp_to_ns(right.header.stamp),
                                       encoding=left.encoding, right_encoding=right.encoding,
                                       odometry=self._wheel_motion(stamp))
        self.diag.mirror(self.frontend.drops, "frontend_", "rejected by the frontend")
        self.diag.mirror({"vo_failures": self.frontend.vo_failures}, "", "frames whose motion the visual odometry "
                         "could not estimate (the constant-velocity prediction stood in)")
        self.diag.mirror({"track_gaps": self.frontend.track_gaps}, "", "pairs after a gap in the stream: "
                         "every track ended")
        if self.frontend.fiducials is not None:
            self.diag.mirror(self.frontend.fiducials.drops, "frontend_", "tags not reported")
        if obs is not None:
            self.publish_visual_odometry()
            for sighting in obs.sightings:
                self.sighting_pub.publish(sighting_to_msg(sighting, obs.stamp_ns))
            self.pub.publish(observations_to_cloud(obs, f"{self.cfg.robot}/base_link"))
        if scan is not None:
            self.scan_pub.publish(obstacle_scan_to_laser(scan, f"{self.cfg.robot}/base_link"))


    def publish_visual_odometry(self) -> None:
        """The frame's visual odometry on ``visual_odom`` (odom frame ``<robot>/visual_odom``)."""
        from mrslam_core.pipelines.odometry import propagate_planar, visual_step_covariance

        vo = self.frontend.odometry
        dt = 0.0 if self._vo_stamp is None else (vo.stamp_ns - self._vo_stamp) * 1e-9
        prev = planar_from_matrix(vo.pose @ np.linalg.inv(vo.delta))
        step_cov = visual_step_covariance(vo.cov)
        self._vo_cov = propagate_planar(self._vo_cov, prev, planar_from_matrix(vo.delta), step_cov)
        self._vo_stamp = vo.stamp_ns
        self.vo_pub.publish(visual_odometry_msg(vo, self._vo_cov, dt, f"{self.cfg.robot}/visual_odom",
                                                f"{self.cfg.robot}/base_link"))


def main(argv: list[str] | None = None) -> int:
    return run_node(FrontendNode, argv)


if __name__ == "__main__":
    sys.exit(main())
