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
        assert node.scans_inserted > 0 and node.drops["scan_without_pose"] <= 1
    finally:
        rclpy.shutdown()


def test_a_scan_is_laid_at_the_pose_of_its_own_stamp_not_the_latest():
    """The latest pose is often a frame newer or older than a scan; the wall of a scan stamped
    at t1 must land where the robot faced at t1 (east), not at t2 (north)."""
    import rclpy
    from sensor_msgs.msg import LaserScan

    from mrslam_ros.conversions import ns_to_stamp, pose_with_covariance
    from mrslam_ros.explore_node import ExploreNode

    rclpy.init()
    try:
        node = ExploreNode()
        t1, t2 = 1_000_000_000, 1_200_000_000
        east, north = np.array([5.0, 5.0, 0.0]), np.array([5.0, 5.0, np.pi / 2])
        scan = LaserScan(angle_min=-0.2, angle_increment=0.02, range_min=0.0, range_max=4.0)
        scan.ranges = [2.0] * 21
        node.on_pose("robot1", pose_with_covariance(east, np.eye(3) * 1e-4, t1, "map"))
        node.on_pose("robot1", pose_with_covariance(north, np.eye(3) * 1e-4, t2, "map"))
        scan.header.stamp = ns_to_stamp(t1)
        node.on_scan("robot1", scan)
        def hit_near(x, y):
            centres = node.grid.centre_of(np.argwhere(node.grid.logodds > 0))
            return bool(len(centres)) and np.linalg.norm(centres - [x, y], axis=1).min() < 0.1

        assert hit_near(7.0, 5.0) and not hit_near(5.0, 7.0)
        # a scan whose pose never came is counted once the next pose passes it, and not laid
        scan.header.stamp = ns_to_stamp(t2 + 100_000_000)
        node.on_scan("robot1", scan)
        node.on_pose("robot1", pose_with_covariance(north, np.eye(3) * 1e-4, t2 + 200_000_000, "map"))
        scan.header.stamp = ns_to_stamp(t2 + 300_000_000)
        node.on_scan("robot1", scan)
        node.on_pose("robot1", pose_with_covariance(north, np.eye(3) * 1e-4, t2 + 300_000_000, "map"))
        assert node.scans_inserted == 2 and node.drops["scan_without_pose"] == 1
        assert hit_near(5.0, 7.0)
    finally:
        rclpy.shutdown()


def test_a_bumper_contact_is_an_obstacle_at_the_robots_pose_and_bad_clouds_are_counted():
    """robot1 at (5, 5) facing north touches at (0.18, 0.19) in base_link: the map point (4.81,
    5.18). A contact before any pose, one on robot2 (standing 0.7 m west; the touch 0.3 m off
    robot1's left side is 0.4 m from it) and a cloud without y are counted or dropped, not laid."""
    import rclpy

    from mrslam_ros.conversions import contacts_to_cloud, pose_with_covariance
    from mrslam_ros.explore_node import ExploreNode

    rclpy.init()
    try:
        node = ExploreNode(parameter_overrides=[rclpy.parameter.Parameter("robots", value=["robot1", "robot2"])])
        touch = contacts_to_cloud(np.array([[0.18, 0.19]]), 1, "robot1/base_link")
        node.on_bumper("robot1", touch)
        assert node.drops["bumper_without_pose"] == 1 and not node.grid.observed.size
        north = np.array([5.0, 5.0, np.pi / 2])
        node.on_pose("robot1", pose_with_covariance(north, np.eye(3) * 1e-4, 1, "map"))
        node.on_pose("robot2", pose_with_covariance(np.array([4.3, 5.0, 0.0]), np.eye(3) * 1e-4, 1, "map"))
        node.on_bumper("robot1", touch)
        np.testing.assert_allclose(node.grid.centre_of(np.argwhere(node.grid.occupied())), [[4.85, 5.15]], atol=1e-9)
        node.on_bumper("robot1", contacts_to_cloud(np.array([[0.0, 0.3]]), 2, "robot1/base_link"))  # on robot2
        bad = contacts_to_cloud(np.array([[0.1, 0.0]]), 3, "robot1/base_link")
        bad.fields = bad.fields[:1]
        node.on_bumper("robot1", bad)
        assert node.explorer.bumped_cells == 1 and node.drops["bad_bumper"] == 1
    finally:
        rclpy.shutdown()


def test_the_node_logs_counters_of_either_severity_as_they_grow():
    """rclpy raises when one call site logs at two severities; a blocked turn (a warning) after a
    long turn (information) once took the node down mid-run."""
    import rclpy

    from mrslam_ros.conversions import pose_with_covariance
    from mrslam_ros.explore_node import EVENTS, ExploreNode

    rclpy.init()
    try:
        node = ExploreNode()
        node.on_pose("robot1", pose_with_covariance(np.array([5.0, 5.0, 0.0]), np.eye(3) * 1e-4, 1, "map"))
        grown = []
        counts = node.explorer.controller.counters()
        node.explorer.controller.counters = lambda: dict(counts)

        def step(grid, poses, now):
            name = EVENTS[len(grown) % len(EVENTS)][0]
            counts[name] += 1
            grown.append(name)
            return {}

        node.explorer.step = step
        for _ in range(2 * len(EVENTS)):
            node.control()
        assert {warn for name, warn, _ in EVENTS if name in grown} == {True, False}
        assert all(counts[name] == 2 for name, _, _ in EVENTS)
    finally:
        rclpy.shutdown()


def test_the_published_map_follows_the_grid_as_it_grows():
    """No /map before the first scan; then each /map is the grid as it is: a scan from the east of
    (5, 5) and then one far to the south-west grow it, and the wall cell seen first keeps its value
    at the same map position in both messages."""
    import rclpy
    from sensor_msgs.msg import LaserScan

    from mrslam_ros.conversions import ns_to_stamp, occupancy_to_arrays, pose_with_covariance
    from mrslam_ros.explore_node import ExploreNode

    rclpy.init()
    try:
        node = ExploreNode()
        maps = []
        node.map_pub.publish = maps.append
        node.publish_map()
        assert maps == []
        scan = LaserScan(angle_min=-0.2, angle_increment=0.02, range_min=0.0, range_max=4.0)
        scan.ranges = [2.0] * 21
        for k, pose in enumerate([np.array([5.0, 5.0, 0.0]), np.array([-6.0, -7.0, -np.pi / 2])]):
            stamp = (k + 1) * 1_000_000_000
            node.on_pose("robot1", pose_with_covariance(pose, np.eye(3) * 1e-4, stamp, "map"))
            scan.header.stamp = ns_to_stamp(stamp)
            node.on_scan("robot1", scan)
            node.publish_map()
            if k == 0:  # the wall cells seen first, 2 m east of (5, 5): centres (x, y) [m]
                wall = node.grid.centre_of(np.argwhere(node.grid.occupied()))
        assert node.scans_inserted == 2 and len(maps) == 2 and len(wall) >= 5
        assert np.abs(wall[:, 0] - 7.0).max() < 0.1
        seen = []
        for msg in maps:
            prob, known, origin, res = occupancy_to_arrays(msg)
            assert (msg.info.height, msg.info.width) == prob.shape
            ij = np.floor((wall[:, ::-1] - origin[1::-1]) / res).astype(int)
            seen.append((origin[:2], prob.shape, prob[ij[:, 0], ij[:, 1]], known[ij[:, 0], ij[:, 1]]))
        (o1, s1, p1, k1), (o2, s2, p2, k2) = seen
        assert (o2 < o1).all() and s2[0] > s1[0] and s2[1] > s1[1]
        np.testing.assert_allclose(o2, node.grid.origin)
        assert k1.all() and k2.all() and (p1 > 0.65).all()
        np.testing.assert_array_equal(p1, p2)
    finally:
        rclpy.shutdown()


def test_a_robot_without_a_map_pose_explores_alone_and_its_scans_join_the_team_grid():
    """robot2's poses come in its start frame (an unknown start): its scan (a wall 2 m ahead)
    goes into its own grid, and it gets commands with robot1 in the map. Its join places its
    start frame at (3, 1, 90°) in the map: the wall lands at (3, 3) in the team's grid, and
    robot2 explores with the team. Late poses of its start frame and a third frame are not used."""
    import rclpy
    from sensor_msgs.msg import LaserScan

    from mrslam_ros.conversions import ns_to_stamp, pose_stamped_msg, pose_with_covariance
    from mrslam_ros.explore_node import ExploreNode

    rclpy.init()
    try:
        node = ExploreNode(parameter_overrides=[rclpy.parameter.Parameter("robots", value=["robot1", "robot2"])])
        cov = np.eye(3) * 1e-4
        scan = LaserScan(angle_min=-0.2, angle_increment=0.02, range_min=0.0, range_max=4.0)
        scan.ranges = [2.0] * 21
        node.on_pose("robot1", pose_with_covariance(np.array([5.0, 5.0, 0.0]), cov, 1, "map"))
        node.on_pose("robot2", pose_with_covariance(np.zeros(3), cov, 1, "robot2/start"))
        scan.header.stamp = ns_to_stamp(1)
        node.on_scan("robot2", scan)
        assert "robot2" in node.own and node.explorer.robots == ["robot1"]
        assert not node.grid.observed.size and node.own["robot2"].grid.observed.any()
        node.now_ns = 1
        node.control()  # both robots get a command, each from its own explorer
        node.on_start_pose("robot2", pose_stamped_msg(np.array([3.0, 1.0, np.pi / 2]), 5, "map"))
        assert not node.own and node.explorer.robots == ["robot1", "robot2"]
        walls = node.grid.centre_of(np.argwhere(node.grid.occupied()))
        # the wall spans ±0.2 rad at 2 m: x 3 ± 0.4 m, y 3 m (cells of 0.1 m)
        assert len(walls) and np.abs(walls[:, 1] - 3.0).max() < 0.1 and np.abs(walls[:, 0] - 3.0).max() < 0.5
        node.on_pose("robot2", pose_with_covariance(np.zeros(3), cov, 4, "robot2/start"))  # older than the join
        node.on_pose("robot2", pose_with_covariance(np.zeros(3), cov, 6, "odom"))
        assert not node.own and node.drops["pose_frame"] == 1
        node.on_pose("robot2", pose_with_covariance(np.array([3.0, 1.0, np.pi / 2]), cov, 6, "map"))
        node.control()
        assert set(node.poses) == {"robot1", "robot2"}
    finally:
        rclpy.shutdown()
