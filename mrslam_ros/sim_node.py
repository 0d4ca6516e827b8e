"""The simulated team as a ROS node: /clock, and per robot stereo images with camera_info, wheel
odometry, ground truth, its bumper's contacts (``/<robot>/bumper``, PointCloud2 in base_link, sent
while it touches something), odom -> base_link on /tf and each camera's optical frame on
/tf_static; drives from ``/<robot>/cmd_vel``.

The simulation advances ``steps_per_tick`` physics steps per timer tick; with ``real_time_factor``
> 0 the tick period follows the wall clock, with 0 it runs as fast as it can. Nodes that should
follow the simulated time run with ``use_sim_time:=true``.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
from tf2_msgs.msg import TFMessage

from mrslam_core.frontend.config import FiducialConfig
from mrslam_core.sim.config import SimConfig
from mrslam_core.sim.simulation import Simulation
from mrslam_ros.conversions import (
    array_to_image,
    calibration_to_camera_info,
    contacts_to_cloud,
    matrix_transform_msg,
    ns_to_stamp,
    pose_to_msg,
    transform_msg,
)
from mrslam_ros.params import declare_config, read_config
from mrslam_ros.qos import ODOMETRY_HISTORY, TF_STATIC
from mrslam_ros.spin import run_node


@dataclass(frozen=True)
class SimNodeConfig:
    """The simulator node.

    Attributes:
        robots: number of robots (named robot1..robotK, placed at the world's start poses).
        real_time_factor: simulated seconds per wall second (0: as fast as possible).
        steps_per_tick: physics steps per timer tick.
        wait_for_frontends: hold the simulation at time 0 until every robot's stereo images have
            a subscriber (so no robot's first frames are lost while its frontend starts).
        start_delay: wall seconds to wait after that before time starts [s] (lets late
            subscribers such as a bag recorder discover the graph).
        sim: the simulation.
        fiducials: the robots that carry tags, drawn on their carriers.
    """

    robots: int = 1
    real_time_factor: float = 1.0
    steps_per_tick: int = 5
    wait_for_frontends: bool = False
    start_delay: float = 0.0
    sim: SimConfig = field(default_factory=SimConfig)
    fiducials: FiducialConfig = field(default_factory=FiducialConfig)


class SimNode(Node):
    """Thin wrapper: step the core simulation, convert, publish."""

    def __init__(self, name: str = "sim", **kwargs):
        super().__init__(name, **kwargs)
        declare_config(self, SimNodeConfig())
        self.cfg = read_config(self, SimNodeConfig)
        self.sim = Simulation(self.cfg.sim, fiducials=self.cfg.fiducials)
        self.names = [f"robot{i + 1}" for i in range(self.cfg.robots)]
        for n in self.names:
            self.sim.add_robot(n)
        self.left_cal, self.right_cal = self.sim.camera_infos()
        self.clock_pub = self.create_publisher(Clock, "/clock", 10)
        self.tf_pub = self.create_publisher(TFMessage, "/tf", 100)
        # each robot's cameras on its base (REP-105 optical frames), latched for late subscribers
        self.tf_static_pub = self.create_publisher(TFMessage, "/tf_static", TF_STATIC)
        self.tf_static_pub.publish(TFMessage(transforms=[
            matrix_transform_msg(self.sim.camera_extrinsic(side), 0, f"{n}/base_link", f"{n}/camera_{side}_optical")
            for n in self.names for side in ("left", "right")]))
        self.pubs = {}
        for n in self.names:
            self.pubs[n] = {
                "left": self.create_publisher(Image, f"/{n}/stereo/left/image_raw", 5),
                "right": self.create_publisher(Image, f"/{n}/stereo/right/image_raw", 5),
                "left_info": self.create_publisher(CameraInfo, f"/{n}/stereo/left/camera_info", 5),
                "right_info": self.create_publisher(CameraInfo, f"/{n}/stereo/right/camera_info", 5),
                "odom": self.create_publisher(Odometry, f"/{n}/odom", ODOMETRY_HISTORY),
                "truth": self.create_publisher(Odometry, f"/{n}/ground_truth", 50),
                "bumper": self.create_publisher(PointCloud2, f"/{n}/bumper", 10),
            }
            self.create_subscription(Twist, f"/{n}/cmd_vel", lambda m, n=n: self.on_cmd(n, m), 10)
        dt = self.cfg.steps_per_tick / self.cfg.sim.physics_hz
        period = dt / self.cfg.real_time_factor if self.cfg.real_time_factor > 0 else 1e-3
        self._ready_at: float | None = None if self.cfg.wait_for_frontends else time.monotonic() + self.cfg.start_delay
        self._started = False
        self.create_timer(period, self.tick)

    def _may_start(self) -> bool:
        if self._started:
            return True
        now = time.monotonic()
        if self._ready_at is None:
            if all(self.pubs[n][side].get_subscription_count() > 0 for n in self.names for side in ("left", "right")):
                self._ready_at = now + self.cfg.start_delay
                self.get_logger().info(f"every frontend is subscribed; starting in {self.cfg.start_delay:g} s")
            return False
        self._started = now >= self._ready_at
        return self._started

    def on_cmd(self, name: str, msg: Twist) -> None:
        try:
            self.sim.set_command(name, float(msg.linear.x), float(msg.angular.z))
        except ValueError:
            self.get_logger().warn(f"{name}: unusable cmd_vel dropped", throttle_duration_sec=5.0)

    def tick(self) -> None:
        if not self._may_start():
            self.clock_pub.publish(Clock(clock=ns_to_stamp(self.sim.time_ns)))
            return
        for _ in range(self.cfg.steps_per_tick):
            self.sim.step()
        now = self.sim.time_ns
        stamp = ns_to_stamp(now)
        self.clock_pub.publish(Clock(clock=stamp))
        transforms = []
        for n in self.names:
            pose, twist = self.sim.odometry(n)
            odom = Odometry()
            odom.header.stamp = stamp
            odom.header.frame_id, odom.child_frame_id = f"{n}/odom", f"{n}/base_link"
            odom.pose.pose = pose_to_msg(pose)
            odom.twist.twist.linear.x, odom.twist.twist.angular.z = float(twist[0]), float(twist[1])
            self.pubs[n]["odom"].publish(odom)
            truth = Odometry()
            truth.header.stamp = stamp
            truth.header.frame_id, truth.child_frame_id = "map", f"{n}/base_link"
            truth.pose.pose = pose_to_msg(self.sim.ground_truth(n))
            self.pubs[n]["truth"].publish(truth)
            transforms.append(transform_msg(pose, now, f"{n}/odom", f"{n}/base_link"))
            touch = self.sim.contacts(n)
            if len(touch):
                self.pubs[n]["bumper"].publish(contacts_to_cloud(touch, now, f"{n}/base_link"))
        self.tf_pub.publish(TFMessage(transforms=transforms))
        for n in self.sim.frames_due():
            frame = self.sim.render_stereo(n)
            p = self.pubs[n]
            enc = "mono8" if frame.left.ndim == 2 else "rgb8"
            p["left_info"].publish(calibration_to_camera_info(self.left_cal, frame.stamp_ns, f"{n}/camera_left_optical"))
            p["right_info"].publish(calibration_to_camera_info(self.right_cal, frame.stamp_ns, f"{n}/camera_right_optical"))
            p["left"].publish(array_to_image(frame.left, enc, frame.stamp_ns, f"{n}/camera_left_optical"))
            p["right"].publish(array_to_image(frame.right, enc, frame.stamp_ns, f"{n}/camera_right_optical"))

    def destroy_node(self) -> None:
        self.sim.close()
        super().destroy_node()


def main(argv: list[str] | None = None) -> int:
    return run_node(SimNode, argv)


if __name__ == "__main__":
    sys.exit(main())
