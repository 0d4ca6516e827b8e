"""Stereo visual odometry: exact motions, outliers, covariance consistency, predicted pixels.

Frames: rectified left optical (x right, y down, z forward); the motion is the current camera's
pose in the previous one, p_prev = R·p_cur + t.
"""

from __future__ import annotations

import numpy as np
import pytest

from mrslam_core.frontend.frontend import _body_covariance
from mrslam_core.frontend.odometry import CameraMotion, estimate_motion, predict_pixels, so3_exp
from mrslam_core.geometry.stereo import project, triangulation_covariance

F, CX, CY, B = 700.0, 600.0, 180.0, 0.54
GATE = dict(gate=14.16, ransac_px=2.0, ransac_iterations=200, min_inliers=8)


def _scene(seed: int, n: int = 60):
    """Points 4-30 m ahead in the previous camera, a motion of 1.2 m forward with a 2° yaw,
    and the points' stereo measurements (row, column, disparity) in both frames."""
    rng = np.random.default_rng(seed)
    prev = np.column_stack([rng.uniform(-8, 8, n), rng.uniform(-2, 1.5, n), rng.uniform(4, 30, n)])
    rot = so3_exp([0.0, np.radians(2.0), 0.0])  # yaw of an optical frame is about y
    trans = np.array([0.05, -0.01, 1.2])
    cur = (prev - trans) @ rot  # Rᵀ(p − t)
    return prev, cur, rot, trans


def _cov(points: np.ndarray, sigma=(0.2, 0.5, 0.5)) -> np.ndarray:
    r, c, d = project(points, F, CX, CY, B).T
    return triangulation_covariance(r, c, d, F, CX, CY, B, *sigma)


def test_noiseless_pairs_give_the_motion_exactly_and_outliers_are_found():
    prev, cur, rot, trans = _scene(0)
    cur_xy = project(cur, F, CX, CY, B)[:, [1, 0]]
    bad = cur.copy()
    bad[[3, 11]] += [[0.0, 0.0, 3.0], [1.0, 0.0, 0.0]]  # a wrong disparity, a look-alike
    m = estimate_motion(prev, _cov(prev), cur_xy, bad, _cov(cur), F, CX, CY, **GATE)
    assert m is not None
    np.testing.assert_allclose(m.rotation, rot, atol=1e-9)
    np.testing.assert_allclose(m.translation, trans, atol=1e-8)
    assert list(np.flatnonzero(~m.inliers)) == [3, 11]


def test_too_few_pairs_give_no_motion():
    prev, cur, _, _ = _scene(1, n=5)
    xy = project(cur, F, CX, CY, B)[:, [1, 0]]
    assert estimate_motion(prev, _cov(prev), xy, cur, _cov(cur), F, CX, CY, **GATE) is None


def test_the_motion_covariance_is_consistent_with_its_error():
    """Seeded Monte Carlo: pixel noise drawn as the stereo model says; the motion's normalised
    error (δθ, δt)ᵀ Σ⁻¹ (δθ, δt) must be χ²(6) distributed (mean 6)."""
    prev, cur, rot, trans = _scene(2, n=80)
    sigma = np.array([0.2, 0.5, 0.5])  # d, r, c [px]
    rng = np.random.default_rng(7)
    nees = []
    for _ in range(100):
        meas = []
        for pts in (prev, cur):
            r, c, d = project(pts, F, CX, CY, B).T
            r, c, d = r + rng.normal(0, sigma[1], r.size), c + rng.normal(0, sigma[2], c.size), d + rng.normal(0, sigma[0], d.size)
            z = F * B / d
            meas.append((np.column_stack([B * (c - CX) / d, B * (r - CY) / d, z]), np.column_stack([c, r]),
                         triangulation_covariance(r, c, d, F, CX, CY, B, *sigma)))
        (p0, _, c0), (p1, xy1, c1) = meas
        m = estimate_motion(p0, c0, xy1, p1, c1, F, CX, CY, **GATE)
        assert m is not None
        err_rot = np.array(__import__("cv2").Rodrigues(m.rotation.T @ rot)[0]).reshape(3)
        e = np.r_[err_rot, trans - m.translation]
        nees.append(e @ np.linalg.solve(m.cov, e))
    mean = float(np.mean(nees))
    assert 4.5 <= mean <= 8.0  # χ²(6) mean 6; the 100-trial mean has a standard error of 0.35


def test_predicted_pixels_are_the_projection_and_their_covariance_grows_with_the_prior():
    prev, cur, rot, trans = _scene(3, n=10)
    small = CameraMotion(rot, trans, np.diag([1e-12] * 6), np.zeros(0, bool))
    uv, s, front = predict_pixels(small, prev, np.zeros((10, 3, 3)), F, CX, CY, 1.0)
    np.testing.assert_allclose(uv, project(cur, F, CX, CY, B)[:, [1, 0]], atol=1e-9)
    assert front.all()
    np.testing.assert_allclose(s[:, 0, 0], 1.0, atol=0.05)  # the keypoint noise alone
    loose = CameraMotion(rot, trans, np.diag([1e-4] * 3 + [0.0] * 3), np.zeros(0, bool))
    _, s2, _ = predict_pixels(loose, prev, np.zeros((10, 3, 3)), F, CX, CY, 1.0)
    # a rotation δθ of the camera moves u = f·x/z by f·(−xy/z², 1 + x²/z², −y/z)·δθ (and the sign
    # does not matter for the variance)
    x, y = cur[:, 0] / cur[:, 2], cur[:, 1] / cur[:, 2]
    expected = F**2 * 1e-4 * ((x * y) ** 2 + (1 + x**2) ** 2 + y**2) + 1.0
    np.testing.assert_allclose(s2[:, 0, 0], expected, rtol=1e-9)


def test_a_camera_motion_in_base_link_terms():
    """A camera looking along base x: 1 m along optical z is 1 m along base x, and a turn about
    optical +y (down) is a turn about base −z."""
    t_bc = np.array([[0.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0, 0, 0, 1.0]])
    a = 0.1
    m = CameraMotion(so3_exp([0.0, a, 0.0]), np.array([0.0, 0.0, 1.0]),
                     np.diag([1e-4, 2e-4, 3e-4, 1e-2, 2e-2, 3e-2]), np.zeros(0, bool))
    body = t_bc @ m.matrix() @ np.linalg.inv(t_bc)
    np.testing.assert_allclose(body[:3, 3], [1.0, 0.0, 0.0], atol=1e-12)
    assert np.arctan2(body[1, 0], body[0, 0]) == pytest.approx(-a)  # optical +y (down) is base −z
    cov = _body_covariance(m, t_bc)
    # the axes permute: base (x, y, z) = optical (z, −x, −y)
    np.testing.assert_allclose(np.diag(cov), [3e-4, 1e-4, 2e-4, 3e-2, 1e-2, 2e-2], rtol=1e-5)


def test_wheel_odometry_becomes_the_cameras_motion_prior(small_rig):
    """A base_link turn of 0.1 rad and 0.3 m forward, seen from the rig's camera (0.1 m ahead of
    base_link, 0.5 m up, looking along base x): the camera turns about its −y (optical y is
    down) and moves along its z, and sideways by the lever arm; uncertain by the prior's σ."""
    from mrslam_core.frontend import Frontend
    from mrslam_core.frontend.odometry import planar_motion

    fe = Frontend(small_rig)
    body = planar_motion(np.array([0.3, 0.0, 0.1]))
    m = fe.motion_prior(body)
    rect = small_rig.t_base_rect
    np.testing.assert_allclose(rect @ m.matrix() @ np.linalg.inv(rect), body, atol=1e-12)
    np.testing.assert_allclose(m.rotation, so3_exp([0.0, -0.1, 0.0]), atol=1e-12)
    # the camera's own translation: 0.3 m forward plus the lever arm 0.1 m swung by 0.1 rad
    lever = np.array([0.1 * np.cos(0.1) - 0.1, 0.1 * np.sin(0.1), 0.0])
    t_body = np.array([0.3, 0.0, 0.0]) + lever
    np.testing.assert_allclose(m.translation, [-t_body[1], 0.0, t_body[0]], atol=1e-12)
    c = fe.cfg
    np.testing.assert_allclose(np.diag(m.cov), [c.prior_sigma_rot**2] * 3 + [c.prior_sigma_trans**2] * 3)
    assert fe.motion_prior() is None  # no odometry and no frame yet: no prediction
