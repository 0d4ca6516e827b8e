"""Message conversions, with messages built by hand (no running graph)."""

import numpy as np
import pytest

from mrslam_core.frontend.camera import CameraCalibration
from mrslam_core.types import ObservationSet
from mrslam_ros.conversions import (
    ConversionError,
    array_to_image,
    calibration_to_camera_info,
    camera_info_to_calibration,
    cloud_to_observations,
    image_to_array,
    msg_to_pose,
    observations_to_cloud,
    occupancy_msg,
    odometry_to_pose,
    path_msg,
    pose_with_covariance,
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
                                                  ("bgr8", (4, 6, 3), np.uint8), ("mono16", (4, 6), np.uint16)])
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
