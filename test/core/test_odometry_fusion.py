"""Odometry sources of the central mapper: wheel and visual steps fused by their covariances."""

from __future__ import annotations

import numpy as np
import pytest

from mrslam_core.pipelines.odometry import (OdometryFusion, OdometrySource, fuse_steps, propagate_planar,
                                            visual_step_covariance)
from mrslam_core.slam.config import MotionConfig


def test_two_equally_certain_steps_average_and_a_certain_one_wins():
    step, cov = fuse_steps(np.array([1.0, 0.0, 0.1]), np.eye(3) * 0.01, np.array([1.2, 0.2, 0.3]), np.eye(3) * 0.01)
    np.testing.assert_allclose(step, [1.1, 0.1, 0.2], atol=1e-12)
    np.testing.assert_allclose(cov, np.eye(3) * 0.005, atol=1e-15)
    step, _ = fuse_steps(np.array([1.0, 0.0, 0.0]), np.eye(3) * 1e-2, np.array([2.0, 0.0, 0.0]), np.eye(3) * 1e-8)
    assert step[0] == pytest.approx(2.0, abs=1e-5)
    # angles across ±π are averaged on one branch
    step, _ = fuse_steps(np.array([0.0, 0.0, np.pi - 0.1]), np.eye(3), np.array([0.0, 0.0, -np.pi + 0.1]), np.eye(3))
    assert abs(abs(step[2]) - np.pi) < 1e-12


def test_a_slipping_wheel_is_outvoted_by_a_certain_visual_odometry():
    """Wheels at 50 Hz read 10 % long; the camera (10 Hz) sees the true 1 m/s with 1 cm/s of
    noise. The fused odometry follows the camera; the first fused pose is the wheel's."""
    motion = MotionConfig(alpha1=0.0, alpha2=0.0, alpha3=0.0, alpha4=0.0, var_xy_per_m=0.01, var_theta_per_m=1e-4)
    fusion = OdometryFusion(motion)
    cov = np.diag([1e-4, 1e-4, 1e-6])  # twist covariance [(m/s)², (rad/s)²]
    fused = []
    t_wheel = np.arange(0, 10.001, 0.02)
    t_cam = np.arange(0, 10.001, 0.1)
    events = sorted([(t, 0) for t in t_wheel] + [(t, 1) for t in t_cam], key=lambda e: (e[0], -e[1]))
    for t, kind in events:
        ns = int(round(t * 1e9))
        if kind == 0:
            fused += fusion.add_wheel(ns, np.array([1.1 * t, 0.0, 0.0]))
        else:
            fused += fusion.add_visual(ns, np.array([t + 5.0, 2.0, 0.0]), cov)  # its own odom frame
    assert len(fused) == len(t_cam) and fusion.dropped == 0
    np.testing.assert_allclose(fused[0][1], [0.0, 0.0, 0.0])  # starts at the wheel pose
    assert fused[-1][1][0] == pytest.approx(10.0, abs=0.01)  # the camera's 10 m, not the wheels' 11 m


def test_visual_poses_wait_for_the_wheels_to_reach_their_stamp():
    fusion = OdometryFusion(MotionConfig())
    fusion.add_wheel(0, np.zeros(3))
    assert fusion.add_visual(100, np.zeros(3), np.eye(3)) == []  # the wheels are at 0 ns
    out = fusion.add_wheel(200, np.array([0.2, 0.0, 0.0]))
    assert [s for s, _ in out] == [100]
    np.testing.assert_allclose(out[0][1], [0.1, 0.0, 0.0])  # the wheel pose interpolated at 100 ns


def test_each_source_passes_its_own_stream_and_ignores_the_other():
    pose, cov = np.array([1.0, 2.0, 0.5]), np.eye(3)
    wheel = OdometrySource("wheel", MotionConfig())
    assert (wheel.uses_wheel, wheel.uses_visual, wheel.fusion) == (True, False, None)
    (stamp, out), = wheel.wheel(10, pose)
    assert stamp == 10 and np.array_equal(out, pose)
    assert wheel.visual(20, pose, cov) == [] and wheel.dropped == 0
    visual = OdometrySource("visual", MotionConfig())
    assert visual.wheel(10, pose) == [] and [s for s, _ in visual.visual(20, pose, cov)] == [20]
    fused = OdometrySource("fused", MotionConfig())
    assert fused.uses_wheel and fused.uses_visual and isinstance(fused.fusion, OdometryFusion)
    assert fused.wheel(0, np.zeros(3)) == [] and fused.visual(100, pose, cov) == []  # wheels at 0 ns
    assert [s for s, _ in fused.wheel(200, np.array([0.2, 0.0, 0.0]))] == [100]
    with pytest.raises(ValueError, match="odometry source must be one of"):
        OdometrySource("gps", MotionConfig())


def test_planar_covariance_propagation():
    q = np.diag([0.01, 0.02, 0.03])
    np.testing.assert_allclose(propagate_planar(np.zeros((3, 3)), np.zeros(3), np.array([1.0, 0, 0]), q), q)
    # a heading variance before a 2 m step becomes 4 × that variance across the track
    c = propagate_planar(np.diag([0.0, 0.0, 0.01]), np.zeros(3), np.array([2.0, 0.0, 0.0]), np.zeros((3, 3)))
    assert c[1, 1] == pytest.approx(0.04) and c[0, 0] == pytest.approx(0.0) and c[1, 2] == pytest.approx(0.02)
    # facing +y, a step along the body x moves along the map y
    c = propagate_planar(np.zeros((3, 3)), np.array([0.0, 0.0, np.pi / 2]), np.array([1.0, 0, 0]), q)
    np.testing.assert_allclose(np.diag(c), [0.02, 0.01, 0.03], atol=1e-15)


def test_the_visual_step_covariance_is_the_planar_part_of_the_frame_motion():
    # VisualOdometry.cov orders (δθx, δθy, δθz, δtx, δty, δtz); the planar step is (x, y, θ)
    cov6 = np.diag([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    cov6[3, 2] = cov6[2, 3] = 0.5
    np.testing.assert_allclose(visual_step_covariance(cov6), [[4.0, 0, 0.5], [0, 5.0, 0], [0.5, 0, 3.0]])


def test_the_team_refuses_an_unknown_odometry_source():
    from mrslam_core.pipelines.team import TeamConfig

    assert TeamConfig(odometry="fused").odometry == "fused"
    with pytest.raises(ValueError, match="odometry must be one of"):
        TeamConfig(odometry="gps")
