"""Pairwise 2D alignment: exact recovery, RANSAC with wrong matches, and clear rejections.

Frames: the transform (tx, ty, θ) moves source-map points into the target map, p_t = R p_s + t.
"""

import numpy as np
import pytest

from mrslam_core.fusion.alignment import (
    alignment_error,
    apply_transform,
    explained,
    match_descriptors,
    ransac_align,
    rigid_transform_2d,
    transform_cramer_rao,
    transform_information_covariance,
)
from mrslam_core.fusion.config import FusionConfig
from mrslam_core.fusion.maps import LandmarkMap
from mrslam_core.fusion.synthetic import make_map_pair


def test_closed_form_recovers_a_known_transform_exactly():
    rng = np.random.default_rng(0)
    src = rng.uniform(-5, 5, (12, 2))
    truth = np.array([1.5, -0.7, 2.8])  # θ beyond π/2 on purpose
    dst = apply_transform(truth, src)
    np.testing.assert_allclose(rigid_transform_2d(src, dst), truth, atol=1e-12)
    # weights do not matter without noise; two points are enough
    np.testing.assert_allclose(rigid_transform_2d(src, dst, rng.uniform(0.1, 5, 12)), truth, atol=1e-12)
    np.testing.assert_allclose(rigid_transform_2d(src[:2], dst[:2]), truth, atol=1e-12)


def test_weighted_fit_follows_the_weights():
    # a corrupted third pair with (almost) zero weight is ignored
    src = np.array([[0.0, 0.0], [4.0, 0.0], [0.0, 3.0]])
    truth = np.array([2.0, 1.0, 0.3])
    dst = apply_transform(truth, src)
    dst[2] += [1.0, -1.0]
    est = rigid_transform_2d(src, dst, np.array([1.0, 1.0, 1e-12]))
    np.testing.assert_allclose(est, truth, atol=1e-9)


def test_mutual_descriptor_matches():
    t = np.eye(4, dtype=np.float32)
    s = np.array([[0, 0, 0.9, 0], [1, 0, 0, 0], [0.95, 0, 0, 0], [0, 0, 0, 0.1]], np.float32)
    pairs = match_descriptors(t, s, 0.5, mutual=True)
    # source 0 ↔ target 2; target 0's nearest source is row 1 (exact), so row 2 loses; row 3 too far
    assert {tuple(p) for p in pairs} == {(2, 0), (0, 1)}
    assert len(match_descriptors(t, s, 0.5, mutual=False)) == 3


def test_noiseless_maps_align_exactly():
    rng = np.random.default_rng(1)
    truth = np.array([-4.0, 7.0, -1.2])
    pair = make_map_pair(rng, truth, 40, 0.5, 0.0, noise=0.0)
    al = ransac_align(pair.target, pair.source, FusionConfig())
    assert al.accepted, al.reason
    np.testing.assert_allclose(al.transform, truth, atol=1e-9)
    assert al.rmse < 1e-9 and al.inliers.size == 20


@pytest.mark.parametrize("seed", range(5))
def test_ransac_with_30_percent_outlier_matches(seed):
    rng = np.random.default_rng(seed)
    truth = np.array([3.0, -2.0, 0.7])
    pair = make_map_pair(rng, truth, 100, 0.5, 0.3, noise=0.03)
    al = ransac_align(pair.target, pair.source, FusionConfig(seed=seed))
    assert al.accepted, al.reason
    wrong = np.isin(pair.source.ids[al.matches[:, 1]], pair.outliers)
    assert 0.28 <= wrong.mean() <= 0.32  # the matches really hold 30 % wrong ones
    assert not wrong[al.inliers].any()  # and none of them survives as an inlier
    dt, dth = alignment_error(al.transform, truth)
    assert dt <= 0.05 and np.degrees(dth) <= 1.0, (dt, np.degrees(dth))


def test_disjoint_maps_are_not_merged_and_say_why():
    rng = np.random.default_rng(3)
    pair = make_map_pair(rng, np.array([1.0, 2.0, 0.5]), 50, 0.0, 0.0, noise=0.03)
    al = ransac_align(pair.target, pair.source, FusionConfig())
    assert not al.accepted
    assert "do not overlap" in al.reason and "0 descriptor matches" in al.reason
    # same maps, but every descriptor match points at the wrong place (all swapped)
    pair = make_map_pair(rng, np.array([1.0, 2.0, 0.5]), 50, 0.4, 1.0, noise=0.03)
    al = ransac_align(pair.target, pair.source, FusionConfig())
    assert not al.accepted and len(al.matches) == 20
    assert "inliers of 20 descriptor matches" in al.reason and "need 6" in al.reason


def test_rejects_large_residual_and_collapsed_inliers():
    rng = np.random.default_rng(4)
    pair = make_map_pair(rng, np.array([0.5, 0.5, 0.1]), 40, 0.5, 0.0, noise=0.12)
    al = ransac_align(pair.target, pair.source, FusionConfig(inlier_distance=0.6, max_residual=0.1))
    assert not al.accepted and "RMSE" in al.reason
    # eight matched landmarks within a few cm of each other: rotation undetermined
    pts = np.column_stack([rng.normal(0, 0.02, (8, 2)), np.zeros(8)])
    desc = np.eye(8, dtype=np.float32)
    m = LandmarkMap(pts, np.broadcast_to(np.eye(3) * 1e-4, (8, 3, 3)), desc)
    al = ransac_align(m, m, FusionConfig())
    assert not al.accepted and "rotation undetermined" in al.reason


def test_far_transforms_at_30_percent_wrong_matches_are_accurate_where_the_maps_overlap():
    """The experiment's setting (|t| up to 14 m): the translation measured at the shared landmarks'
    centroid and θ hold 0.05 m / 1°, and the error is what the noise allows (Cramér–Rao, χ²(3))."""
    nees, worst_c, worst_th = [], 0.0, 0.0
    for s in range(20):
        rng = np.random.default_rng(1000 + s)
        truth = np.array([rng.uniform(-10, 10), rng.uniform(-10, 10), rng.uniform(-np.pi, np.pi)])
        pair = make_map_pair(rng, truth, 100, 0.5, 0.3, noise=0.03)
        al = ransac_align(pair.target, pair.source, FusionConfig(seed=s))
        assert al.accepted, al.reason
        good = pair.source.means[np.isin(pair.source.ids, np.setdiff1d(pair.common, pair.outliers)), :2]
        cen = good.mean(0, keepdims=True)
        worst_c = max(worst_c, float(np.linalg.norm(apply_transform(al.transform, cen) - apply_transform(truth, cen))))
        worst_th = max(worst_th, np.degrees(alignment_error(al.transform, truth)[1]))
        e = al.transform - truth
        e[2] = (e[2] + np.pi) % (2 * np.pi) - np.pi
        nees.append(e @ np.linalg.solve(transform_cramer_rao(truth, good, 0.03), e))
    assert worst_c <= 0.05 and worst_th <= 1.0, (worst_c, worst_th)
    # an efficient estimator: mean of χ²(3) is 3 (20 trials: ±0.55); a fit that wasted the
    # information (e.g. unweighted with an outlier inside) would sit far above
    assert 1.5 <= np.mean(nees) <= 5.0, np.mean(nees)


def test_landmark_covariance_bound_equals_the_isotropic_one_and_weighs_each_pair():
    rng = np.random.default_rng(11)
    t = np.array([1.0, -2.0, 2.4])
    src = rng.uniform(-3, 3, (6, 2))
    iso = np.broadcast_to(np.eye(2) * 0.05**2, (6, 2, 2))
    np.testing.assert_allclose(transform_information_covariance(t, src, iso, iso),
                               transform_cramer_rao(t, src, 0.05), rtol=1e-10)
    # one pair far less certain: the bound lies between dropping it and counting it as certain
    loose = iso.copy()
    loose[0] = np.eye(2) * 1.0
    c = transform_information_covariance(t, src, loose, iso)
    drop = transform_cramer_rao(t, src[1:], 0.05)
    assert np.trace(transform_cramer_rao(t, src, 0.05)) < np.trace(c) < np.trace(drop)


def test_explained_counts_the_matches_a_pose_explains():
    src = np.array([[1.0, 0.0, 0.5], [2.0, 1.0, 0.5], [0.0, 3.0, 0.5]])
    pose = np.array([1.0, 2.0, np.pi / 2])
    # pose ⊕ src: (1, 3), (0, 4), (-2, 2); the third 0.2 m off, outside 0.1 m, inside 0.3 m
    dst = np.array([[1.0, 3.0, 0.5], [0.0, 4.0, 0.5], [-1.8, 2.0, 0.5]])
    cov = np.tile(np.eye(3) * 1e-4, (3, 1, 1))
    desc = np.eye(3, dtype=np.float32)
    target, source = LandmarkMap(dst, cov, desc), LandmarkMap(src, cov, desc)
    matches = np.array([[0, 0], [1, 1], [2, 2]])
    assert explained(pose, target, source, matches, 0.1).sum() == 2
    assert explained(pose, target, source, matches, 0.3).sum() == 3
    assert explained(np.zeros(3), target, source, matches, 0.1).sum() == 0
    assert explained(pose, target, source, matches[:0], 0.1).sum() == 0


def test_explained_with_a_gate_uses_both_covariances_and_the_floor():
    # a stereo point 2 m ahead: depth σ 0.2 m, lateral σ 0.01 m, in the source (base_link) frame;
    # target landmarks with σ 0.01 m per axis, the second 0.2 m to the side of the point
    src = np.array([[2.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    cov_src = np.tile(np.diag([0.2**2, 0.01**2, 1.0]), (2, 1, 1))
    dst = np.array([[2.0, 0.0, 0.0], [2.0, 0.2, 0.0]])
    cov_dst = np.tile(np.diag([0.01**2, 0.01**2, 1.0]), (2, 1, 1))
    desc = np.eye(2, dtype=np.float32)
    target, source = LandmarkMap(dst, cov_dst, desc), LandmarkMap(src, cov_src, desc)
    matches = np.array([[0, 0], [1, 1]])
    zero = np.zeros(3)
    assert explained(zero, target, source, matches, 0.3).tolist() == [True, True]
    # sideways the second is 0.2 m against σ √2e-4 m: d² = 200 > 9.21
    assert explained(zero, target, source, matches, 0.3, gate=9.21).tolist() == [True, False]
    # under a pose turned 3° the point moves 2·sin 3° = 0.105 m sideways: d² ≈ 55 and 45
    turned = np.array([0.0, 0.0, np.radians(3.0)])
    assert explained(turned, target, source, matches, 0.3).tolist() == [True, True]
    assert explained(turned, target, source, matches, 0.3, gate=9.21).tolist() == [False, False]
    # a pose-noise floor of 0.05 m (variance + 0.0025 m²) takes both inside: d² ≈ 4.1 and 3.3
    assert explained(turned, target, source, matches, 0.3, gate=9.21, floor=0.05).tolist() == [True, True]
