"""The simulator node on a live graph: cmd_vel drives a robot, odometry, ground truth, /clock and
stereo images with camera_info come out."""

import time

import pytest

pytestmark = pytest.mark.ros


def test_sim_node_drives_and_renders():
    import rclpy
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import CameraInfo, Image

    from mrslam_ros.conversions import camera_info_to_calibration, image_to_array, msg_to_pose
    from mrslam_ros.sim_node import SimNode

    rclpy.init()
    try:
        node = SimNode(parameter_overrides=[Parameter("sim.world", value="small"),
                                            Parameter("real_time_factor", value=0.0)])
        probe = rclpy.create_node("probe")
        got = {"img": [], "info": [], "odom": [], "truth": [], "clock": []}
        probe.create_subscription(Image, "/robot1/stereo/left/image_raw", got["img"].append, 10)
        probe.create_subscription(CameraInfo, "/robot1/stereo/right/camera_info", got["info"].append, 10)
        probe.create_subscription(Odometry, "/robot1/odom", got["odom"].append, 100)
        probe.create_subscription(Odometry, "/robot1/ground_truth", got["truth"].append, 100)
        probe.create_subscription(Clock, "/clock", got["clock"].append, 100)
        cmd = probe.create_publisher(Twist, "/robot1/cmd_vel", 10)
        ex = SingleThreadedExecutor()
        ex.add_node(node)
        ex.add_node(probe)
        twist = Twist()
        twist.linear.x = 0.3
        end = time.time() + 20
        while time.time() < end and node.sim.time_ns < 3e9:
            cmd.publish(twist)
            ex.spin_once(timeout_sec=0.01)
        for _ in range(20):
            ex.spin_once(timeout_sec=0.01)
        assert node.sim.time_ns >= 3e9
        assert got["img"] and got["info"] and got["clock"]
        assert image_to_array(got["img"][-1]).shape == (240, 320)
        assert camera_info_to_calibration(got["info"][-1]).P[0, 3] < 0  # right camera: −f·b
        travelled = msg_to_pose(got["truth"][-1].pose.pose)[0] - msg_to_pose(got["truth"][0].pose.pose)[0]
        assert travelled > 0.3  # cmd_vel moved the robot forward
        assert abs(msg_to_pose(got["odom"][-1].pose.pose)[0] - travelled) < 0.2
        node.destroy_node()
    finally:
        rclpy.shutdown()
