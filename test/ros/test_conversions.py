"""Message conversions, with messages built by hand (no running graph)."""

import numpy as np
import pytest

from mrslam_core.frontend.camera import CameraCalibration
from mrslam_core.types import ObservationSet, RobotSighting
from mrslam_ros.conversions import (
    ConversionError,
    array_to_image,
    calibration_to_camera_info,
    camera_info_to_calibration,
    cloud_to_contacts,
    cloud_to_observations,
    contacts_to_cloud,
    image_to_array,
    msg_to_pose,
    msg_to_sighting,
    observations_to_cloud,
    occupancy_msg,
    odometry_to_pose,
    path_msg,
    pose_with_covariance,
    sighting_to_msg,
    stamp_to_ns,
    transform_msg,
)


def _obs(b=4, d=8):
    rng = np.random.default_rng(0)
    a = rng.standard_normal((b, 3, 3))
    cov = (a @ a.transpose(0, 2, 1) + np.eye(3)).astype(np.float32).astype(float)
    return ObservationSet("robot1", 1_500_000_123, rng.standard_normal((b, 3)).astype(np.float32).astype(float), cov,
                          rng.standard_normal((b, d)).astype(np.float32), np.arange(b) + 7)


def test_observation_cloud_round_trip():
    obs = _obs()
    msg = observations_to_cloud(obs, "robot1/base_link")
    assert [f.name for f in msg.fields][:3] == ["x", "y", "z"] and msg.fields[-1].count == 8
    back = cloud_to_observations(msg, "robot1")
    np.testing.assert_allclose(back.z, obs.z, rtol=1e-6)
    np.testing.assert_allclose(back.cov, obs.cov, rtol=1e-6)
    np.testing.assert_array_equal(back.track_ids, obs.track_ids)
    np.testing.assert_array_equal(back.descriptors, obs.descriptors)
    assert back.stamp_ns == 1_500_000_123


def test_malformed_clouds_are_rejected():
    msg = observations_to_cloud(_obs(), "f")
    short = observations_to_cloud(_obs(), "f")
    short.data = bytes(msg.data)[:-5]
    with pytest.raises(ConversionError, match="bytes"):
        cloud_to_observations(short, "r")
    no_cov = observations_to_cloud(_obs(), "f")
    no_cov.fields = [f for f in no_cov.fields if f.name != "cyy"]
    with pytest.raises(ConversionError, match="lacks fields"):
        cloud_to_observations(no_cov, "r")
    bad_type = observations_to_cloud(_obs(), "f")
    bad_type.fields[0].datatype = 1  # INT8
    with pytest.raises(ConversionError, match="datatype"):
        cloud_to_observations(bad_type, "r")
    big = observations_to_cloud(_obs(), "f")
    big.is_bigendian = True
    with pytest.raises(ConversionError, match="big-endian"):
        cloud_to_observations(big, "r")


@pytest.mark.parametrize("encoding,shape,dtype", [("mono8", (4, 6), np.uint8), ("rgb8", (4, 6, 3), np.uint8),
                                                  ("bgr8", (4, 6, 3), np.uint8), ("mono16", (4, 6), np.uint16),
                                                  ("8UC1", (4, 6), np.uint8), ("16UC1", (4, 6), np.uint16)])
def test_image_round_trip(encoding, shape, dtype):
    arr = (np.arange(np.prod(shape)) % 250).astype(dtype).reshape(shape)
    msg = array_to_image(arr, encoding, 5, "cam")
    np.testing.assert_array_equal(image_to_array(msg), arr)


def test_bad_images():
    msg = array_to_image(np.zeros((4, 6), np.uint8), "mono8", 0, "c")
    msg.encoding = "yuv422"
    with pytest.raises(ConversionError, match="encoding"):
        image_to_array(msg)
    msg = array_to_image(np.zeros((4, 6), np.uint8), "mono8", 0, "c")
    msg.data = bytes(msg.data)[:10]
    with pytest.raises(ConversionError, match="bytes"):
        image_to_array(msg)
    msg = array_to_image(np.zeros((4, 6), np.uint8), "mono8", 0, "c")
    msg.step = 3
    with pytest.raises(ConversionError, match="step"):
        image_to_array(msg)
    # a padded row (step > width) is read correctly
    padded = array_to_image(np.arange(24, dtype=np.uint8).reshape(4, 6), "mono8", 0, "c")
    rows = np.frombuffer(bytes(padded.data), np.uint8).reshape(4, 6)
    padded.data = np.hstack([rows, np.zeros((4, 2), np.uint8)]).tobytes()
    padded.step = 8
    np.testing.assert_array_equal(image_to_array(padded), np.arange(24).reshape(4, 6))


def test_camera_info_round_trip_and_empty():
    k = np.array([[400.0, 0, 160], [0, 400, 120], [0, 0, 1]])
    p = np.hstack([k, [[-48.0], [0], [0]]])
    cal = CameraCalibration(320, 240, k, np.zeros(5), np.eye(3), p)
    back = camera_info_to_calibration(calibration_to_camera_info(cal, 1, "cam"))
    np.testing.assert_array_equal(back.P, p)
    from sensor_msgs.msg import CameraInfo

    with pytest.raises(ConversionError, match="empty"):
        camera_info_to_calibration(CameraInfo())


def test_poses_paths_tf_grid():
    from nav_msgs.msg import Odometry

    pose = np.array([1.0, -2.0, 2.5])
    cov = np.diag([0.1, 0.2, 0.03])
    msg = pose_with_covariance(pose, cov, 3_000_000_001, "map")
    np.testing.assert_allclose(msg_to_pose(msg.pose.pose), pose)
    assert np.array(msg.pose.covariance).reshape(6, 6)[5, 5] == pytest.approx(0.03)
    odo = Odometry()
    odo.header.stamp = msg.header.stamp
    odo.pose = msg.pose
    stamp, p, c = odometry_to_pose(odo)
    assert stamp == 3_000_000_001 and np.allclose(p, pose) and np.allclose(c, cov)
    path = path_msg(np.array([pose, pose]), np.array([1, 2]), "map")
    assert len(path.poses) == 2 and stamp_to_ns(path.header.stamp) == 2
    tf = transform_msg(pose, 5, "map", "robot1/odom")
    assert tf.child_frame_id == "robot1/odom" and tf.transform.translation.y == -2.0
    grid = occupancy_msg(np.array([[0.1, 0.9], [0.5, 0.5]]), np.array([[True, True], [True, False]]), np.zeros(2), 0.1, 0)
    assert list(grid.data) == [10, 90, 50, -1] and grid.info.width == 2


def test_obstacle_scan_round_trip_keeps_free_space():
    from mrslam_core.frontend.obstacles import ObstacleScan
    from mrslam_ros.conversions import laser_to_scan, obstacle_scan_to_laser

    obs = ObstacleScan(stamp_ns=7, angle_min=-0.1, angle_increment=0.1, ranges=np.array([1.0, np.inf, np.inf]),
                       free_ranges=np.array([1.0, 2.5, 0.0]), range_max=4.0, points=np.zeros((1, 2)))
    scan = laser_to_scan(obstacle_scan_to_laser(obs, "robot1/base_link"))
    np.testing.assert_allclose(scan.bearings, [-0.05, 0.05])
    np.testing.assert_allclose(scan.ranges, [1.0, 2.5])
    assert scan.hit.tolist() == [True, False]


# ----------------------------------------------------------------------------- added conversions
def test_cloud_layouts_rows_and_bad_values():
    from mrslam_ros.conversions import observations_to_cloud

    obs = _obs(b=4, d=3)
    msg = observations_to_cloud(obs, "f")
    # the same points as 2 rows of 2, each row padded by 8 bytes
    step = msg.point_step
    rows = np.frombuffer(bytes(msg.data), np.uint8).reshape(2, 2 * step)
    msg.height, msg.width, msg.row_step = 2, 2, 2 * step + 8
    msg.data = np.hstack([rows, np.full((2, 8), 255, np.uint8)]).tobytes()
    back = cloud_to_observations(msg, "r")
    np.testing.assert_allclose(back.z, obs.z, rtol=1e-6)
    np.testing.assert_array_equal(back.track_ids, obs.track_ids)
    msg.row_step = step  # shorter than a row
    with pytest.raises(ConversionError, match="row_step"):
        cloud_to_observations(msg, "r")
    zero = observations_to_cloud(obs, "f")
    zero.point_step = 0
    with pytest.raises(ConversionError, match="point_step"):
        cloud_to_observations(zero, "r")
    wide = observations_to_cloud(obs, "f")
    wide.fields[-1].count = 50  # descriptor runs past the point
    with pytest.raises(ConversionError, match="does not fit"):
        cloud_to_observations(wide, "r")
    nan = observations_to_cloud(ObservationSet("r", 0, np.full((1, 3), np.nan), np.eye(3)[None]), "f")
    with pytest.raises(ConversionError, match="non-finite"):
        cloud_to_observations(nan, "r")
    empty = cloud_to_observations(observations_to_cloud(ObservationSet("r", 9, np.zeros((0, 3)), np.zeros((0, 3, 3))), "f"), "r")
    assert len(empty) == 0 and empty.stamp_ns == 9


def test_uint32_track_ids_and_float64_points_are_read():
    from sensor_msgs.msg import PointCloud2, PointField

    names = ["x", "y", "z", "cxx", "cxy", "cxz", "cyy", "cyz", "czz"]
    fields = [PointField(name=n, offset=8 * i, datatype=PointField.FLOAT64, count=1) for i, n in enumerate(names)]
    fields.append(PointField(name="track_id", offset=72, datatype=PointField.UINT32, count=1))
    rec = np.zeros(1, dtype=[(n, "<f8") for n in names] + [("track_id", "<u4")])
    rec["x"], rec["cxx"], rec["cyy"], rec["czz"], rec["track_id"] = 2.5, 1.0, 2.0, 3.0, 4_000_000_000
    msg = PointCloud2(height=1, width=1, fields=fields, point_step=76, row_step=76, data=rec.tobytes())
    obs = cloud_to_observations(msg, "r")
    assert obs.z[0, 0] == 2.5 and obs.track_ids[0] == 4_000_000_000 and obs.descriptors.shape == (1, 0)
    np.testing.assert_allclose(np.diag(obs.cov[0]), [1.0, 2.0, 3.0])


def test_odometry_pose_path_pose_array_round_trips():
    from mrslam_ros.conversions import (
        path_to_poses,
        pose_array_msg,
        pose_array_to_poses,
        pose_to_odometry,
        pose_with_covariance_to_pose,
    )

    pose, cov = np.array([1.0, 2.0, -3.0]), np.array([[0.1, 0.01, 0.0], [0.01, 0.2, 0.0], [0.0, 0.0, 0.05]])
    odo = pose_to_odometry(pose, cov, 42, "robot1/odom", "robot1/base_link", twist=(0.3, -0.1))
    assert odo.child_frame_id == "robot1/base_link" and odo.twist.twist.angular.z == -0.1
    stamp, p, c = odometry_to_pose(odo)
    assert stamp == 42 and np.allclose(p, pose) and np.allclose(c, cov)
    stamp, p, c = pose_with_covariance_to_pose(pose_with_covariance(pose, cov, 7, "map"))
    assert stamp == 7 and np.allclose(p, pose) and np.allclose(c, cov)
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.5, 3.1], [2.0, -1.0, -1.2]])
    back, stamps = path_to_poses(path_msg(poses, np.array([10, 20, 30]), "map"))
    np.testing.assert_allclose(back, poses, atol=1e-12)
    assert stamps.tolist() == [10, 20, 30]
    pa = pose_array_msg(poses, 5, "map")
    assert len(pa.poses) == 3 and pa.header.frame_id == "map"
    np.testing.assert_allclose(pose_array_to_poses(pa), poses, atol=1e-12)
    with pytest.raises(ConversionError, match="\\(M, 3\\)"):
        pose_array_msg(np.zeros((3, 2)), 0, "map")
    odo.pose.covariance[0] = float("nan")
    with pytest.raises(ConversionError, match="not finite"):
        pose_with_covariance_to_pose(odo)  # an Odometry's pose field has the same layout


def test_tf_clock_and_transforms():
    from mrslam_ros.conversions import clock_msg, tf_message, transform_to_pose

    tf = transform_msg(np.array([1.0, -2.0, 0.7]), 3_000_000_005, "map", "robot2/odom")
    stamp, parent, child, pose = transform_to_pose(tf)
    assert (stamp, parent, child) == (3_000_000_005, "map", "robot2/odom") and np.allclose(pose, [1.0, -2.0, 0.7])
    msg = tf_message([tf, tf])
    assert type(msg).__name__ == "TFMessage" and len(msg.transforms) == 2
    c = clock_msg(12_000_000_003)
    assert c.clock.sec == 12 and c.clock.nanosec == 3


def test_occupancy_from_log_odds_and_back():
    from mrslam_ros.conversions import log_odds_to_occupancy, occupancy_to_arrays

    lo = np.array([[0.0, 2.0, -2.0], [0.0, 0.0, np.log(9.0)]])
    msg = log_odds_to_occupancy(lo, np.array([-1.0, 2.0]), 0.05, 11)
    assert list(msg.data) == [-1, 88, 12, -1, -1, 90]
    assert msg.info.width == 3 and msg.info.height == 2 and msg.info.resolution == pytest.approx(0.05)
    prob, known, origin, res = occupancy_to_arrays(msg)
    assert known.tolist() == [[False, True, True], [False, False, True]]
    np.testing.assert_allclose(prob, [[0.5, 0.88, 0.12], [0.5, 0.5, 0.9]])
    np.testing.assert_allclose(origin, [-1.0, 2.0, 0.0])
    assert res == pytest.approx(0.05)
    msg.data = list(msg.data)[:-1]
    with pytest.raises(ConversionError, match="5 cells"):
        occupancy_to_arrays(msg)


def test_landmark_ellipsoids():
    from visualization_msgs.msg import Marker

    from mrslam_ros.conversions import landmark_markers

    mean = np.array([[1.0, 2.0, 0.5], [0.0, 0.0, 0.0]])
    # second landmark: sigma 0.3 m along (1, 1, 0)/√2, 0.1 m along (1, −1, 0)/√2 and 0.2 m along z
    u, v = np.array([1.0, 1.0, 0.0]) / np.sqrt(2), np.array([1.0, -1.0, 0.0]) / np.sqrt(2)
    cov2 = 0.09 * np.outer(u, u) + 0.01 * np.outer(v, v) + 0.04 * np.outer([0, 0, 1.0], [0, 0, 1.0])
    msg = landmark_markers(mean, np.stack([np.diag([0.01, 0.04, 0.0]), cov2]), 3, "map", n_sigma=2.0)
    assert msg.markers[0].action == Marker.DELETEALL and len(msg.markers) == 3
    m0, m1 = msg.markers[1], msg.markers[2]
    assert m0.type == Marker.SPHERE and m0.id == 0 and m0.pose.position.y == 2.0
    assert sorted([m0.scale.x, m0.scale.y, m0.scale.z]) == pytest.approx([0.01, 0.4, 0.8])  # min size for σ = 0
    assert [m1.scale.x, m1.scale.y, m1.scale.z] == pytest.approx([0.4, 0.8, 1.2])  # ascending eigenvalues
    # the marker's x axis (smallest) must be ±v, its z axis (largest) ±u
    from scipy.spatial.transform import Rotation

    q = m1.pose.orientation
    rot = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
    assert abs(rot[:, 0] @ v) == pytest.approx(1.0) and abs(rot[:, 2] @ u) == pytest.approx(1.0)
    with pytest.raises(ConversionError, match="cov must be"):
        landmark_markers(mean, np.zeros((3, 3, 3)), 0)


def test_diagnostics_message_and_counters():
    from diagnostic_msgs.msg import DiagnosticStatus

    from mrslam_ros.conversions import diagnostics_msg, diagnostics_to_counters
    from mrslam_ros.diagnostics import Counters

    now = [0.0]
    logged = []
    c = Counters(log=logged.append, log_period=5.0, clock=lambda: now[0])
    c.count("unknown_robot", "robot9")
    c.count("unknown_robot")
    now[0] = 6.0
    c.count("unknown_robot")
    c.count("wrong_frame", n=2)
    c.set("update_ms_p95", 12.5)
    assert len(logged) == 3 and "robot9" in logged[0] and "3 so far" in logged[1]
    counters, level, message = c.snapshot()
    assert level == "warn" and message == "dropping: unknown_robot, wrong_frame"
    assert counters == {"drops.unknown_robot": 3, "drops.wrong_frame": 2, "drops.total": 5, "update_ms_p95": 12.5}
    assert c.snapshot()[1] == "ok"  # nothing new since
    msg = diagnostics_msg("/slam", counters, 1_000_000_000, level, message)
    st = msg.status[0]
    assert st.level == DiagnosticStatus.WARN and st.name == "/slam" and msg.header.stamp.sec == 1
    assert [(kv.key, kv.value) for kv in st.values][:2] == [("drops.total", "5"), ("drops.unknown_robot", "3")]
    assert diagnostics_to_counters(msg)["/slam"]["update_ms_p95"] == 12.5
    with pytest.raises(ConversionError, match="level"):
        diagnostics_msg("x", {}, 0, level="fatal")


def test_points_marker_round_trip_and_clear():
    from mrslam_ros.conversions import marker_points, points_marker

    xy = np.array([[1.0, 2.0], [-3.5, 0.25]])
    msg = points_marker(xy, 5_000_000_000, "map", "frontiers", size=0.3)
    assert len(msg.markers) == 1 and msg.markers[0].header.frame_id == "map"
    assert msg.markers[0].scale.x == pytest.approx(0.3)
    np.testing.assert_array_equal(marker_points(msg), [[1.0, 2.0, 0.0], [-3.5, 0.25, 0.0]])
    assert marker_points(points_marker(np.zeros((0, 2)), 0, "map", "frontiers")).shape == (0, 3)
    with pytest.raises(ConversionError):
        points_marker(np.array([[np.nan, 0.0]]), 0, "map", "frontiers")


def test_sighting_round_trip_and_bad_sightings():
    # robot2 2 m away at 120° in robot1's base_link, range σ 0.05 m, bearing σ 0.02 rad, correlated
    cov = np.array([[0.05**2, 0.0004], [0.0004, 0.02**2]])
    s = RobotSighting("robot1", "robot2", np.array([2.0, np.radians(120.0)]), cov)
    msg = sighting_to_msg(s, 7_000_000_001)
    assert (msg.header.frame_id, msg.child_frame_id) == ("robot1/base_link", "robot2/base_link")
    assert msg.pose.pose.position.x == pytest.approx(-1.0) and msg.pose.pose.position.y == pytest.approx(np.sqrt(3))
    stamp, back = msg_to_sighting(msg, "robot1")
    assert stamp == 7_000_000_001 and (back.observer, back.target) == ("robot1", "robot2")
    np.testing.assert_allclose(back.z, s.z, atol=1e-12)
    np.testing.assert_allclose(back.cov, cov, atol=1e-12)
    with pytest.raises(ConversionError, match="another robot"):
        msg_to_sighting(msg, "robot3")  # another robot's sighting on this robot's topic
    msg.child_frame_id = "robot1/base_link"
    with pytest.raises(ConversionError, match="another robot"):
        msg_to_sighting(msg, "robot1")  # itself
    msg = sighting_to_msg(s, 1)
    msg.pose.covariance = [0.0] * 36
    with pytest.raises(ConversionError, match="not usable"):
        msg_to_sighting(msg, "robot1")


def test_bumper_contacts_round_trip_and_bad_clouds():
    pts = np.array([[0.185, 0.19], [0.185, -0.05], [-0.265, 0.0]])
    msg = contacts_to_cloud(pts, 3_000_000_007, "robot1/base_link")
    assert msg.header.frame_id == "robot1/base_link" and stamp_to_ns(msg.header.stamp) == 3_000_000_007
    np.testing.assert_allclose(cloud_to_contacts(msg), pts, atol=1e-7)  # float32
    assert cloud_to_contacts(contacts_to_cloud(np.zeros((0, 2)), 1, "f")).shape == (0, 2)
    # an observation cloud has x and y too: read as contacts
    np.testing.assert_allclose(cloud_to_contacts(observations_to_cloud(_obs(), "f")), _obs().z[:, :2], atol=1e-7)
    nan = contacts_to_cloud(np.array([[np.nan, 0.0]]), 1, "f")
    with pytest.raises(ConversionError, match="non-finite"):
        cloud_to_contacts(nan)
    no_y = contacts_to_cloud(pts, 1, "f")
    no_y.fields = [f for f in no_y.fields if f.name != "y"]
    with pytest.raises(ConversionError, match="lacks fields"):
        cloud_to_contacts(no_y)
    short = contacts_to_cloud(pts, 1, "f")
    short.data = bytes(short.data)[:20]
    with pytest.raises(ConversionError, match="bytes"):
        cloud_to_contacts(short)
