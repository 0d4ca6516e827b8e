"""The frontend's visual odometry as nav_msgs/Odometry, and its twist covariance read back; messages
built by hand (no running graph)."""

import math

import numpy as np
import pytest

from mrslam_core.frontend.frontend import VisualOdometry
from mrslam_ros.conversions import ConversionError, odometry_twist_covariance, stamp_to_ns, visual_odometry_msg


def _rot_z(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _transform(rot: np.ndarray, t) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rot, t
    return out


def _vo(dt_yaw: float = 0.02, dt_xyz=(1.2, 0.01, -0.02)) -> VisualOdometry:
    """Base_link at (10, 2, 0.3) turned 0.5 rad, after a step of 1.2 m turning 0.02 rad; the step's
    covariance over (δθ, δt) with every entry distinct, so a wrong reordering shows."""
    a = np.arange(36, dtype=float).reshape(6, 6) / 100.0
    cov = a @ a.T + np.diag([1e-4, 2e-4, 3e-4, 4e-3, 5e-3, 6e-3])
    return VisualOdometry(stamp_ns=1_700_000_123, pose=_transform(_rot_z(0.5), [10.0, 2.0, 0.3]),
                          delta=_transform(_rot_z(dt_yaw), dt_xyz), cov=cov, estimated=True)


def test_pose_header_and_pose_covariance():
    vo = _vo()
    pose_cov = np.array([[0.04, 0.01, 0.002], [0.01, 0.09, 0.003], [0.002, 0.003, 0.0025]])
    msg = visual_odometry_msg(vo, pose_cov, 0.1, "robot1/visual_odom", "robot1/base_link")
    assert stamp_to_ns(msg.header.stamp) == 1_700_000_123
    assert (msg.header.frame_id, msg.child_frame_id) == ("robot1/visual_odom", "robot1/base_link")
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    assert (p.x, p.y, p.z) == pytest.approx((10.0, 2.0, 0.3))
    assert (q.x, q.y, q.z, q.w) == pytest.approx((0.0, 0.0, math.sin(0.25), math.cos(0.25)), abs=1e-12)
    cov = np.asarray(msg.pose.covariance).reshape(6, 6)  # ROS order x y z roll pitch yaw
    np.testing.assert_array_equal(cov[np.ix_([0, 1, 5], [0, 1, 5])], pose_cov)
    assert np.count_nonzero(cov) == np.count_nonzero(pose_cov)  # z, roll, pitch: nothing


def test_a_tilted_pose_keeps_its_3d_orientation():
    vo = _vo()
    roll = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # 90° about x
    vo = VisualOdometry(vo.stamp_ns, _transform(roll, [0.0, 0.0, 0.0]), vo.delta, vo.cov, True)
    q = visual_odometry_msg(vo, np.eye(3), 0.1, "o", "b").pose.pose.orientation
    assert (q.x, q.y, q.z, q.w) == pytest.approx((math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)), abs=1e-12)


def test_twist_is_the_step_over_dt_with_its_covariance_reordered_and_scaled():
    vo, dt = _vo(), 0.1
    msg = visual_odometry_msg(vo, np.eye(3), dt, "robot1/visual_odom", "robot1/base_link")
    lin, ang = msg.twist.twist.linear, msg.twist.twist.angular
    assert (lin.x, lin.y, lin.z) == pytest.approx((12.0, 0.1, -0.2))
    assert (ang.x, ang.y, ang.z) == pytest.approx((0.0, 0.0, 0.2), abs=1e-12)
    twist_cov = np.asarray(msg.twist.covariance).reshape(6, 6)  # ROS order vx vy vz wx wy wz
    for i, j in [(0, 0), (1, 1), (2, 2), (0, 2), (2, 1)]:  # translation ↔ translation
        assert twist_cov[i, j] == pytest.approx(vo.cov[3 + i, 3 + j] / dt**2, rel=1e-12)
    for i, j in [(3, 3), (5, 5), (3, 5)]:  # rotation ↔ rotation
        assert twist_cov[i, j] == pytest.approx(vo.cov[i - 3, j - 3] / dt**2, rel=1e-12)
    assert twist_cov[0, 5] == pytest.approx(vo.cov[3, 2] / dt**2, rel=1e-12)  # vx ↔ ωz
    assert twist_cov[5, 0] == pytest.approx(vo.cov[2, 3] / dt**2, rel=1e-12)
    np.testing.assert_allclose(twist_cov, twist_cov.T)
    # read back: the planar part (vx, vy, ωz), the same as the core's (δx, δy, δθz) block / dt²
    planar = odometry_twist_covariance(msg)
    np.testing.assert_allclose(planar, vo.cov[np.ix_([3, 4, 2], [3, 4, 2])] / dt**2, rtol=1e-12)
    # twice the time between frames: a quarter of the twist variance
    slow = odometry_twist_covariance(visual_odometry_msg(vo, np.eye(3), 2 * dt, "o", "b"))
    np.testing.assert_allclose(slow, planar / 4, rtol=1e-12)


def test_first_frame_has_no_twist_and_a_bad_covariance_is_refused():
    msg = visual_odometry_msg(_vo(), np.eye(3), 0.0, "robot1/visual_odom", "robot1/base_link")
    t = msg.twist.twist
    assert (t.linear.x, t.linear.y, t.angular.z) == (0.0, 0.0, 0.0)
    np.testing.assert_array_equal(odometry_twist_covariance(msg), np.zeros((3, 3)))
    cov = list(msg.twist.covariance)
    cov[7] = float("nan")  # vy, vy
    msg.twist.covariance = cov
    with pytest.raises(ConversionError, match="twist covariance is not finite"):
        odometry_twist_covariance(msg)
