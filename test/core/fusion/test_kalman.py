"""Stationary Kalman fusion of matched landmarks (004 eqs. 4–7, corrected) against hand values."""

import numpy as np

from mrslam_core.fusion.kalman import fuse_maps, kalman_fuse
from mrslam_core.fusion.maps import LandmarkMap


def test_fusion_with_a_quarter_turn_by_hand():
    # map 1 (target): landmark at (1, 2, 0), Σ1 = diag(0.04, 0.01, 1)
    # map 2 (source): the same landmark at (0.5, 0, 0) in its frame, Σ = diag(0.09, 0.01, 1);
    # source frame at (1, 1.6) turned +90°: p' = R p + t = (1, 2.1, 0), Σ2 = R Σ Rᵀ = diag(0.01, 0.09, 1)
    # K = Σ1(Σ1 + Σ2)⁻¹ = diag(0.8, 0.1, 0.5); C = C1 + K(C2 − C1) = (1, 2.01, 0);
    # Σ = (I − K)Σ1 = diag(0.008, 0.009, 0.5)
    target = LandmarkMap(np.array([[1.0, 2.0, 0.0]]), np.diag([0.04, 0.01, 1.0])[None],
                         np.array([[1.0, 0.0]], np.float32), np.array([3]))
    source = LandmarkMap(np.array([[0.5, 0.0, 0.0], [2.0, 0.0, 0.3]]),
                         np.stack([np.diag([0.09, 0.01, 1.0]), np.diag([0.04, 0.01, 0.02])]),
                         np.array([[0.0, 1.0], [0.5, 0.5]], np.float32), np.array([1, 2]))
    out = fuse_maps(target, source, np.array([1.0, 1.6, np.pi / 2]), np.array([[0, 0]]))
    np.testing.assert_allclose(out.map.means[0], [1.0, 2.01, 0.0], atol=1e-12)
    np.testing.assert_allclose(out.map.covs[0], np.diag([0.008, 0.009, 0.5]), atol=1e-12)
    # descriptor: mean weighted by counts 3 and 1; counts add up
    np.testing.assert_allclose(out.map.descriptors[0], [0.75, 0.25], atol=1e-7)
    assert out.map.counts[0] == 4
    # the unmatched source landmark is carried over, moved: (2, 0, .3) -> (1, 3.6, .3), Σ turned
    assert len(out.map) == 2 and out.source_rows.tolist() == [0, 1]
    np.testing.assert_allclose(out.map.means[1], [1.0, 3.6, 0.3], atol=1e-12)
    np.testing.assert_allclose(out.map.covs[1], np.diag([0.01, 0.04, 0.02]), atol=1e-12)


def test_covariance_is_rotated_R_sigma_Rt():
    # θ = 45°, Σ = diag(0.09, 0.01): R Σ Rᵀ = [[0.05, 0.04], [0.04, 0.05]] (the paper's RᵀΣR
    # would give −0.04: the inverse rotation)
    m = LandmarkMap(np.zeros((1, 3)), np.diag([0.09, 0.01, 1.0])[None])
    moved = m.transformed(np.array([0.0, 0.0, np.pi / 4]))
    np.testing.assert_allclose(moved.covs[0, :2, :2], [[0.05, 0.04], [0.04, 0.05]], atol=1e-12)


def test_kalman_step_equals_information_form():
    rng = np.random.default_rng(0)
    a = rng.standard_normal((5, 3, 3))
    b = rng.standard_normal((5, 3, 3))
    s1 = a @ a.transpose(0, 2, 1) + 0.1 * np.eye(3)
    s2 = b @ b.transpose(0, 2, 1) + 0.1 * np.eye(3)
    c1, c2 = rng.standard_normal((5, 3)), rng.standard_normal((5, 3))
    c, s = kalman_fuse(c1, s1, c2, s2)
    info = np.linalg.inv(s1) + np.linalg.inv(s2)
    s_ref = np.linalg.inv(info)
    c_ref = (s_ref @ (np.linalg.solve(s1, c1[..., None]) + np.linalg.solve(s2, c2[..., None])))[..., 0]
    np.testing.assert_allclose(s, s_ref, atol=1e-10)
    np.testing.assert_allclose(c, c_ref, atol=1e-10)
    # fused uncertainty is below both inputs (004 fig. 5)
    assert np.all(np.linalg.det(s) < np.minimum(np.linalg.det(s1), np.linalg.det(s2)))


def test_dropped_source_landmarks_are_left_out():
    t = LandmarkMap(np.zeros((2, 3)), np.broadcast_to(np.eye(3), (2, 3, 3)))
    s = LandmarkMap(np.ones((3, 3)), np.broadcast_to(np.eye(3), (3, 3, 3)))
    out = fuse_maps(t, s, np.zeros(3), np.array([[1, 2]]), drop_source=np.array([0]))
    assert len(out.map) == 3 and out.source_rows.tolist() == [-1, 2, 1]
