"""Exact answers for SE(2) algebra and stereo triangulation with its covariance (000 eq. 12).

Frames: optical = x right, y down, z forward; base_link = x forward, y left, z up.
"""

import numpy as np
import pytest

from mrslam_core.geometry import se2
from mrslam_core.geometry.stereo import (
    optical_to_body,
    project,
    triangulate,
    triangulation_covariance,
    triangulation_jacobian,
)


def test_compose_and_inverse_exact():
    a = np.array([1.0, 2.0, np.pi / 2])
    b = np.array([1.0, 0.0, 0.0])
    np.testing.assert_allclose(se2.compose(a, b), [1.0, 3.0, np.pi / 2], atol=1e-12)
    np.testing.assert_allclose(se2.compose(a, se2.inverse(a)), [0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(se2.between(a, se2.compose(a, b)), b, atol=1e-12)


def test_wrap_and_quaternion_round_trip():
    th = np.array([-3 * np.pi, -0.5, 0.0, 2.0, 7.0])
    w = se2.wrap_angle(th)
    assert np.all((w >= -np.pi) & (w < np.pi))
    np.testing.assert_allclose(se2.quaternion_to_yaw(se2.yaw_to_quaternion(w)), w, atol=1e-12)


def test_transform_points_rotates_xy_keeps_z():
    pose = np.array([1.0, -1.0, np.pi])
    pts = np.array([[2.0, 0.0, 0.7]])
    np.testing.assert_allclose(se2.transform_points(pose, pts), [[-1.0, -1.0, 0.7]], atol=1e-12)


def test_triangulation_exact():
    # f = 500 px, b = 0.1 m, principal point (320, 240): a point at (0.2, -0.1, 5) m
    f, cx, cy, b = 500.0, 320.0, 240.0, 0.1
    p = np.array([[0.2, -0.1, 5.0]])
    rcd = project(p, f, cx, cy, b)
    np.testing.assert_allclose(rcd, [[230.0, 340.0, 10.0]])  # row, column, disparity
    np.testing.assert_allclose(triangulate(rcd[:, 0], rcd[:, 1], rcd[:, 2], f, cx, cy, b), p)


def test_triangulation_covariance_matches_hand_computation():
    f, cx, cy, b = 500.0, 320.0, 240.0, 0.1
    r, c, d = np.array([230.0]), np.array([340.0]), np.array([10.0])
    sd, sr, sc = 1.0, 10.0, 10.0
    # J columns (d, r, c): x = b(c-cx)/d, y = b(r-cy)/d, z = f b / d
    jac = np.array([[-0.1 * 20 / 100, 0.0, 0.01], [-0.1 * -10 / 100, 0.01, 0.0], [-50 / 100, 0, 0]])
    np.testing.assert_allclose(triangulation_jacobian(r, c, d, f, cx, cy, b)[0], jac)
    expected = jac @ np.diag([sd**2, sr**2, sc**2]) @ jac.T
    got = triangulation_covariance(r, c, d, f, cx, cy, b, sd, sr, sc)[0]
    np.testing.assert_allclose(got, expected)
    assert got[2, 2] == pytest.approx(0.25)  # σz = f b σd / d² = 0.5 m


def test_jacobian_matches_finite_differences():
    f, cx, cy, b = 400.0, 300.0, 200.0, 0.12
    x0 = np.array([12.0, 150.0, 250.0])  # d, r, c

    def tri(v):
        return triangulate(v[1:2], v[2:3], v[0:1], f, cx, cy, b)[0]

    num = np.column_stack([(tri(x0 + e) - tri(x0 - e)) / 2e-6 for e in np.eye(3) * 1e-6])
    np.testing.assert_allclose(triangulation_jacobian(x0[1:2], x0[2:3], x0[0:1], f, cx, cy, b)[0], num, rtol=1e-6)


def test_optical_to_body_rotates_covariance():
    # camera 0.5 m above base_link looking forward: optical z -> body x, optical x -> body -y
    t = np.eye(4)
    t[:3, :3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]
    t[:3, 3] = [0.1, 0.0, 0.5]
    p, cov = optical_to_body(np.array([[1.0, 0.5, 4.0]]), np.diag([1.0, 2.0, 3.0])[None], t)
    np.testing.assert_allclose(p, [[4.1, -1.0, 0.0]])
    np.testing.assert_allclose(cov[0], np.diag([3.0, 1.0, 2.0]))
