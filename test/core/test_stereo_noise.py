"""The stereo noise calibration of `mrslam experiment stereo_frontend`: track pairs moved into the
world by the true poses (exact), and the maximum-likelihood pixel noise recovered from pairs drawn
with a known one."""

from __future__ import annotations

import numpy as np
import pytest

from mrslam_core.experiments.stereo_frontend import MIN_VIEW_CHANGE, PairCollector, TrackPairs, fit_noise
from mrslam_core.frontend import CameraCalibration, StereoRig
from mrslam_core.frontend.frontend import StereoFrame
from mrslam_core.frontend.odometry import planar_motion
from mrslam_core.geometry.se2 import planar_from_matrix
from mrslam_core.geometry.stereo import project, triangulate, triangulation_jacobian

F, CX, CY, B = 400.0, 320.0, 240.0, 0.1


def rig() -> StereoRig:
    k = np.array([[F, 0, CX], [0, F, CY], [0, 0, 1]])
    p_left = np.hstack([k, np.zeros((3, 1))])
    p_right = p_left.copy()
    p_right[0, 3] = -F * B
    t_base_cam = np.eye(4)  # optical (x right, y down, z forward) in base_link (x forward, z up), 0.3 m up
    t_base_cam[:3, :3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]
    t_base_cam[2, 3] = 0.3
    cal = CameraCalibration(640, 480, k, np.zeros(5), np.eye(3), p_left)
    return StereoRig(cal, CameraCalibration(640, 480, k, np.zeros(5), np.eye(3), p_right), t_base_cam)


def frame_of(world_pts: np.ndarray, ids: list[int], pose: np.ndarray, rig: StereoRig, d_shift: np.ndarray) -> StereoFrame:
    """The frame a camera at planar ``pose`` sees of ``world_pts``, disparities shifted by ``d_shift`` [px]."""
    cam = np.linalg.inv(planar_motion(pose) @ rig.t_base_rect)
    rcd = project(world_pts @ cam[:3, :3].T + cam[:3, 3], F, CX, CY, B)
    rcd[:, 2] += d_shift
    n = len(ids)
    return StereoFrame(xy=rcd[:, [1, 0]], disparity=rcd[:, 2], strength=np.ones(n),
                       points=triangulate(rcd[:, 0], rcd[:, 1], rcd[:, 2], F, CX, CY, B), cov=np.zeros((n, 3, 3)),
                       descriptors=np.zeros((n, 8), np.float32), track_ids=np.array(ids, np.int64),
                       track_length=np.ones(n, np.int64))


def test_a_planar_pose_as_a_matrix_and_back():
    pose = np.array([[1.5, -2.0, 0.3], [0.0, 4.0, -3.0]])
    m = np.array([planar_motion(p) for p in pose])
    np.testing.assert_allclose(m[0, :3, :3], [[np.cos(0.3), -np.sin(0.3), 0], [np.sin(0.3), np.cos(0.3), 0], [0, 0, 1]])
    np.testing.assert_allclose(m[1, :3, 3], [0.0, 4.0, 0.0])
    np.testing.assert_allclose(planar_from_matrix(m), pose, atol=1e-15)


def test_pairs_are_the_world_differences_of_a_track_and_a_drop_ends_them():
    r = rig()
    world = np.array([[4.0, 0.5, 0.8], [5.0, -1.0, 0.2], [3.0, 0.2, 0.5], [6.0, 1.0, 1.0]])
    a, b = np.array([0.0, 0.0, 0.1]), np.array([0.5, 0.1, 0.2])
    fa = frame_of(world[:3], [5, 6, 7], a, r, np.zeros(3))
    fb = frame_of(world[[2, 1, 3]], [7, 6, 8], b, r, np.array([0.0, 1.0, 0.0]))  # track 6: 1 px more disparity
    c = PairCollector(r)
    c.add(fa, planar_motion(a))
    c.add(fb, planar_motion(b))
    pairs = c.pairs(np.array([0.2, 0.4, 0.5]))
    assert pairs.nu.shape == (2, 3)  # tracks 7 and 6, in the second frame's order
    np.testing.assert_allclose(pairs.nu[0], 0.0, atol=1e-12)
    # track 6 in frame b: the point the shifted disparity puts nearer the camera, in the world
    wb = planar_motion(b) @ r.t_base_rect
    shifted = wb[:3, :3] @ fb.points[1] + wb[:3, 3]
    np.testing.assert_allclose(pairs.nu[1], shifted - world[1], atol=1e-12)
    assert np.linalg.norm(pairs.nu[1]) > 0.1
    jac = wb[:3, :3] @ triangulation_jacobian(fb.xy[1, 1], fb.xy[1, 0], fb.disparity[1], F, CX, CY, B)
    np.testing.assert_allclose(pairs.jac_b[1], jac, atol=1e-15)
    np.testing.assert_array_equal(pairs.sigma, [0.2, 0.4, 0.5])

    c = PairCollector(r)
    c.add(fa, planar_motion(a))
    c.add(None, planar_motion(a))
    c.add(fb, planar_motion(b))
    assert c.pairs(np.ones(3)).nu.shape == (0, 3)

    # views 5 mm and 0.1° apart: no pairs from renderings; two frames back (lag 2): the pairs of a and b
    for least, expected in (((0.0, 0.0), 3), (MIN_VIEW_CHANGE, 0)):  # a real camera's still frames count
        c = PairCollector(r, min_view_change=least)
        c.add(fa, planar_motion(a))
        c.add(fa, planar_motion(a + [0.005, 0.0, 0.002]))
        assert len(c.pairs(np.ones(3)).nu) == expected
    c = PairCollector(r, lag=2)
    for f, pose in ((fa, a), (fb, b), (fb, b)):
        c.add(f, planar_motion(pose))
    np.testing.assert_allclose(c.pairs(np.ones(3)).nu, pairs.nu, atol=1e-12)


def test_fit_recovers_the_pixel_noise_and_outlier_fraction():
    rng = np.random.default_rng(3)
    n, sigma, eps = 2000, np.array([0.2, 0.35, 0.5]), 0.05
    r, c, d = rng.uniform(20, 460, n), rng.uniform(20, 620, n), rng.uniform(5, 40, n)  # 1-8 m away
    th = rng.uniform(-np.pi, np.pi, n)
    rot = np.zeros((n, 3, 3))
    rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1], rot[:, 2, 2] = np.cos(th), -np.sin(th), np.sin(th), np.cos(th), 1
    ja = rot @ triangulation_jacobian(r, c, d, F, CX, CY, B)
    jb = rot @ triangulation_jacobian(r + 2, c - 5, d * 1.05, F, CX, CY, B)
    scale = np.where(rng.random(n) < eps, 10.0, 1.0)[:, None]
    ea, eb = rng.normal(size=(n, 3)) * sigma * scale, rng.normal(size=(n, 3)) * sigma * scale
    pairs = TrackPairs(np.einsum("nij,nj->ni", jb, eb) - np.einsum("nij,nj->ni", ja, ea), ja, jb, np.ones(3))
    fit, fit_eps = fit_noise(pairs)
    np.testing.assert_allclose(fit, sigma, rtol=0.08)  # measured 0.202, 0.347, 0.476 px
    assert fit_eps == pytest.approx(eps, abs=0.02)  # measured 0.056
