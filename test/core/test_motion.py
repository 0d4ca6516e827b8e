"""The odometry motion model's random walk: it accrues over time while the robot moves, not while
it stands still."""

import numpy as np
import pytest

from mrslam_core.slam.config import MotionConfig
from mrslam_core.slam.motion import predict_motion, sample_motion

WALK = MotionConfig(alpha1=0.0, alpha2=0.0, alpha3=0.0, alpha4=0.0, sigma_xy_rw=0.02, sigma_theta_rw=0.04)


def test_a_still_robot_does_not_diffuse():
    poses = np.tile([1.0, -2.0, 0.5], (200, 1))
    moved = sample_motion(poses, np.zeros(3), WALK, np.random.default_rng(0), dt=14.0)
    assert np.array_equal(moved, poses)
    mean, cov = predict_motion(poses[:1], np.zeros(3), WALK, dt=14.0)
    assert np.array_equal(mean, poses[:1])
    assert np.abs(cov).max() < 1e-11


@pytest.mark.parametrize("delta", [[0.01, 0.0, 0.0], [0.0, 0.0, 0.01]])
def test_a_moving_robot_gets_the_walk_over_the_whole_interval(delta):
    # the alphas are 0, so the covariance is the walk alone: σ²·dt on each axis
    _, cov = predict_motion(np.zeros((1, 3)), np.array(delta), WALK, dt=0.2)
    assert np.diag(cov[0]) == pytest.approx([0.02**2 * 0.2, 0.02**2 * 0.2, 0.04**2 * 0.2], rel=1e-6)
    moved = sample_motion(np.zeros((20000, 3)), np.array(delta), WALK, np.random.default_rng(1), dt=0.2)
    assert moved[:, 2].std() == pytest.approx(0.04 * np.sqrt(0.2), rel=0.03)
