"""The per-robot stereo frontend node (run it in the robot's namespace).

Subscribes ``stereo/{left,right}/image_raw`` and ``stereo/{left,right}/camera_info``, pairs left and
right images whose stamps differ by at most ``max_skew_ns`` (message_filters is not on PyPI:
the pairing is this node's), runs :class:`mrslam_core.frontend.frontend.Frontend`, and publishes
``observations`` (PointCloud2 in ``<robot>/base_link``) and ``scan`` (the pseudo laser scan for the
occupancy grid, LaserScan in ``<robot>/base_link``). Drops are counted, never raised:
missing camera_info, unpaired images, and whatever the frontend itself rejects.
"""

from __future__ import annotations

import sys
from collections import Counter, deque
from dataclasses import dataclass, field

import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image, LaserScan, PointCloud2

from mrslam_core.frontend.camera import StereoRig
from mrslam_core.frontend.config import FrontendConfig
from mrslam_core.frontend.errors import FrontendError
from mrslam_ros.conversions import (
    ConversionError,
    camera_info_to_calibration,
    image_to_array,
    obstacle_scan_to_laser,
    observations_to_cloud,
    stamp_to_ns,
)
from mrslam_ros.params import declare_config, read_config
from mrslam_ros.spin import run_node

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
        frontend: the frontend's own parameters.
    """

    robot: str = "robot1"
    t_base_cam: tuple[float, ...] = _SIM_EXTRINSIC
    max_skew_ns: int = 5_000_000
    queue: int = 5
    frontend: FrontendConfig = field(default_factory=FrontendConfig)


class FrontendNode(Node):
    """Thin wrapper around the frontend core."""

    def __init__(self, name: str = "frontend", **kwargs):
        super().__init__(name, **kwargs)
        declare_config(self, FrontendNodeConfig())
        self.cfg = read_config(self, FrontendNodeConfig)
        self.drops: Counter[str] = Counter()
        self.infos: dict[str, CameraInfo] = {}
        self.images: dict[str, deque] = {"left": deque(maxlen=self.cfg.queue), "right": deque(maxlen=self.cfg.queue)}
        self.frontend = None
        self._rig_key = None
        self.pub = self.create_publisher(PointCloud2, "observations", 10)
        self.scan_pub = self.create_publisher(LaserScan, "scan", 10)
        for side in ("left", "right"):
            self.create_subscription(CameraInfo, f"stereo/{side}/camera_info", lambda m, s=side: self.infos.__setitem__(s, m), 10)
            self.create_subscription(Image, f"stereo/{side}/image_raw", lambda m, s=side: self.on_image(s, m), 10)

    def _ensure_frontend(self) -> bool:
        if "left" not in self.infos or "right" not in self.infos:
            self.drops["no_camera_info"] += 1
            return False
        key = (tuple(self.infos["left"].p), tuple(self.infos["right"].p), tuple(self.infos["left"].d))
        if key != self._rig_key:
            try:
                rig = StereoRig(camera_info_to_calibration(self.infos["left"]), camera_info_to_calibration(self.infos["right"]),
                                np.asarray(self.cfg.t_base_cam, float).reshape(4, 4))
            except (ConversionError, FrontendError, ValueError) as exc:
                self.drops["bad_camera_info"] += 1
                self.get_logger().warn(f"camera_info rejected: {exc}", throttle_duration_sec=5.0)
                return False
            from mrslam_core.frontend.frontend import Frontend

            self.frontend = Frontend(rig, self.cfg.frontend, robot=self.cfg.robot)
            self._rig_key = key
        return True

    def on_image(self, side: str, msg: Image) -> None:
        self.images[side].append(msg)
        other = "right" if side == "left" else "left"
        stamp = stamp_to_ns(msg.header.stamp)
        for partner in list(self.images[other]):
            if abs(stamp_to_ns(partner.header.stamp) - stamp) <= self.cfg.max_skew_ns:
                left, right = (msg, partner) if side == "left" else (partner, msg)
                self.images["left"].clear()
                self.images["right"].clear()
                self.process(left, right)
                return

    def process(self, left: Image, right: Image) -> None:
        if not self._ensure_frontend():
            return
        try:
            l_img, r_img = image_to_array(left), image_to_array(right)
        except ConversionError:
            self.drops["bad_image"] += 1
            return
        obs, scan = self.frontend.step(l_img, r_img, stamp_to_ns(left.header.stamp),
                                    right_stamp_ns=stamp_to_ns(right.header.stamp), encoding=left.encoding,
                                    right_encoding=right.encoding)
        if obs is not None and len(obs):
            self.pub.publish(observations_to_cloud(obs, f"{self.cfg.robot}/base_link"))
        if scan is not None:
            self.scan_pub.publish(obstacle_scan_to_laser(scan, f"{self.cfg.robot}/base_link"))


def main(argv: list[str] | None = None) -> int:
    return run_node(FrontendNode, argv)


if __name__ == "__main__":
    sys.exit(main())
