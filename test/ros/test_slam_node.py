"""The central SLAM node on a live graph: synthetic odometry and observation clouds of two robots
go in over DDS, poses in the map frame come out, closer to the truth than dead reckoning."""

import time

import numpy as np
import pytest

pytestmark = pytest.mark.ros


def test_slam_node_tracks_two_robots():
    import rclpy
    from geometry_msgs.msg import PoseWithCovarianceStamped
    from nav_msgs.msg import Odometry
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import PointCloud2

    from mrslam_core.datasets.synthetic import SyntheticWorld, SyntheticWorldConfig
    from mrslam_core.geometry.se2 import compose
    from mrslam_ros.conversions import msg_to_pose, ns_to_stamp, observations_to_cloud, pose_to_msg
    from mrslam_ros.slam_node import SlamNode

    world = SyntheticWorld(SyntheticWorldConfig(num_robots=2, seed=4, sigma_d=1.0, sigma_r=10.0, sigma_c=10.0))
    starts = world.start_poses()
    rclpy.init()
    try:
        slam = SlamNode(parameter_overrides=[
            Parameter("robots", value=list(world.robots)),
            Parameter("start_poses", value=starts.ravel().tolist()),
            Parameter("filter.num_particles", value=100),
        ])
        feeder = rclpy.create_node("feeder")
        odom_pub = {r: feeder.create_publisher(Odometry, f"/{r}/odom", 100) for r in world.robots}
        obs_pub = {r: feeder.create_publisher(PointCloud2, f"/{r}/observations", 20) for r in world.robots}
        got = {r: [] for r in world.robots}
        for r in world.robots:
            feeder.create_subscription(PoseWithCovarianceStamped, f"/{r}/pose", lambda m, r=r: got[r].append(m), 100)
        ex = SingleThreadedExecutor()
        ex.add_node(slam)
        ex.add_node(feeder)
        end = time.time() + 10
        while time.time() < end and feeder.count_subscribers("/robot1/observations") == 0:
            ex.spin_once(timeout_sec=0.05)
        odom = {r: np.zeros(3) for r in world.robots}
        for r in world.robots:  # odometry starts at the start pose, stamp 0
            m = Odometry()
            m.pose.pose = pose_to_msg(odom[r])
            odom_pub[r].publish(m)
        truth_at = {}
        steps = 60
        for i, (_, true, _, updates) in enumerate(world.run(steps)):
            for k, u in enumerate(updates):
                odom[u.robot] = compose(odom[u.robot], u.odometry)
                m = Odometry()
                m.header.stamp = ns_to_stamp(u.stamp_ns)
                m.header.frame_id = f"{u.robot}/odom"
                m.pose.pose = pose_to_msg(odom[u.robot])
                odom_pub[u.robot].publish(m)
                truth_at[(u.robot, u.stamp_ns)] = true[k]
            for _ in range(3):
                ex.spin_once(timeout_sec=0.01)
            for u in updates:
                obs_pub[u.robot].publish(observations_to_cloud(u.observations, f"{u.robot}/base_link"))
            for _ in range(5):
                ex.spin_once(timeout_sec=0.01)
        end = time.time() + 10
        while time.time() < end and min(len(v) for v in got.values()) < steps - 1:
            ex.spin_once(timeout_sec=0.05)
        for r in world.robots:
            assert len(got[r]) >= steps - 5, (r, len(got[r]), dict(slam.diag.drops))
            last = got[r][-1]
            stamp = last.header.stamp.sec * 1_000_000_000 + last.header.stamp.nanosec
            err = np.linalg.norm(msg_to_pose(last.pose.pose)[:2] - truth_at[(r, stamp)][:2])
            assert err < 0.3, (r, err, dict(slam.diag.drops))
        assert slam.mapper.slam.landmarks.size > 50  # one shared map
    finally:
        rclpy.shutdown()
