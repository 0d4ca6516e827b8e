"""Holding the common frame at its posterior mean while the central map is empty (issue 8)."""

import numpy as np

from mrslam_core.fusion.gauge import hold_gauge, map_is_empty
from mrslam_core.slam.config import FilterConfig
from mrslam_core.slam.filter import MultiRobotFastSLAM


def spread_filter(seed=0):
    rng = np.random.default_rng(seed)
    slam = MultiRobotFastSLAM(FilterConfig(num_particles=5, seed=seed), ["a", "b"], np.zeros((2, 3)))
    slam.poses = rng.normal(0, 0.3, (5, 2, 3))
    slam.poses[:, 1, 2] += np.pi - 0.1  # headings across ±π: the mean must be circular
    slam.log_w = np.log(np.array([0.1, 0.2, 0.3, 0.25, 0.15]))
    slam.pending_cov[0] = np.eye(3) * 0.01
    return slam


def test_empty_map_collapses_every_robot_onto_its_weighted_mean():
    slam = spread_filter()
    w = np.exp(slam.log_w)
    before = slam.poses.copy()
    assert map_is_empty(slam) and hold_gauge(slam)
    for k in range(2):
        xy = w @ before[:, k, :2]
        th = np.arctan2(w @ np.sin(before[:, k, 2]), w @ np.cos(before[:, k, 2]))
        np.testing.assert_allclose(slam.poses[:, k, :2], np.broadcast_to(xy, (5, 2)), atol=1e-12)
        np.testing.assert_allclose(slam.poses[:, k, 2], th, atol=1e-12)
    assert abs(abs(slam.poses[0, 1, 2]) - np.pi) < 0.5  # near ±π, not the linear mean near 0
    assert slam.pending_cov == {}  # undrawn noise of an unobservable frame is dropped
    np.testing.assert_allclose(np.exp(slam.log_w), [0.1, 0.2, 0.3, 0.25, 0.15])


def test_a_map_with_landmarks_is_left_alone():
    slam = spread_filter(1)
    ex = np.zeros((5, 1), bool)
    ex[2] = True  # one particle holds one landmark
    slam.insert_landmarks(np.ones((5, 1, 3)), np.broadcast_to(np.eye(3), (5, 1, 3, 3)).copy(), ex,
                          np.zeros((1, 0), np.float32))
    before = slam.poses.copy()
    assert not map_is_empty(slam) and not hold_gauge(slam)
    np.testing.assert_array_equal(slam.poses, before)
    assert 0 in slam.pending_cov


def test_only_the_frame_robots_are_held():
    """A robot joined before the first landmark keeps its particles (its spread is its join's
    uncertainty); the robots that fix the frame collapse as before."""
    slam = spread_filter(2)
    slam.pending_cov[1] = np.eye(3) * 0.02
    before = slam.poses.copy()
    assert hold_gauge(slam, ["a"])
    np.testing.assert_array_equal(slam.poses[:, 1], before[:, 1])
    assert np.ptp(slam.poses[:, 0], axis=0).max() == 0.0
    assert list(slam.pending_cov) == [1]
