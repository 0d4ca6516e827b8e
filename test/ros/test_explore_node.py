"""The exploration node on a live graph: a pose and a scan in, a map and a drive command out."""

import time

import numpy as np
import pytest

pytestmark = pytest.mark.ros


def test_explore_node_maps_and_drives():
    import rclpy
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import OccupancyGrid
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import LaserScan

    from mrslam_ros.conversions import ns_to_stamp, pose_with_covariance
    from mrslam_ros.explore_node import ExploreNode

    rclpy.init()
    try:
        node = ExploreNode(parameter_overrides=[Parameter("control_period", value=0.05),
                                                Parameter("map_period", value=0.1),
                                                Parameter("pose_timeout", value=0.5)])
        probe = rclpy.create_node("probe")
        cmds, maps = [], []
        probe.create_subscription(Twist, "/robot1/cmd_vel", cmds.append, 10)
        probe.create_subscription(OccupancyGrid, "/map", maps.append, 1)
        pose_pub = probe.create_publisher(type(pose_with_covariance(np.zeros(3), np.eye(3), 0, "map")), "/robot1/pose", 10)
        scan_pub = probe.create_publisher(LaserScan, "/robot1/scan", 10)
        ex = SingleThreadedExecutor()
        ex.add_node(node)
        ex.add_node(probe)
        scan = LaserScan(angle_min=-0.8, angle_increment=0.04, range_min=0.0, range_max=4.0)
        scan.ranges = [3.0] * 40  # a wall 3 m ahead across a 90° view
        scan.header.frame_id = "robot1/base_link"
        end = time.time() + 15
        while time.time() < end and not (maps and any(c.linear.x != 0 or c.angular.z != 0 for c in cmds)):
            now = probe.get_clock().now().nanoseconds
            pose_pub.publish(pose_with_covariance(np.array([5.0, 5.0, 0.0]), np.eye(3) * 1e-4, now, "map"))
            scan.header.stamp = ns_to_stamp(now)
            scan_pub.publish(scan)
            for _ in range(5):
                ex.spin_once(timeout_sec=0.01)
        assert maps, "no /map"
        data = np.array(maps[-1].data)
        assert (data > 65).sum() > 10 and (data == -1).sum() > 0 and ((data >= 0) & (data < 35)).sum() > 100
        assert any(c.linear.x != 0 or c.angular.z != 0 for c in cmds), "no drive command"
        # no more poses (the central node went down): after pose_timeout the robot is stopped
        end = time.time() + 1.5
        while time.time() < end:
            ex.spin_once(timeout_sec=0.01)
        assert cmds[-1].linear.x == 0 and cmds[-1].angular.z == 0
        assert node.drops["stale_pose"] > 0
        assert node.drops["scan_before_pose"] <= 1
    finally:
        rclpy.shutdown()
