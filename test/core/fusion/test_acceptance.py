"""The χ² acceptance of joins (issue 28): exact residual sums, the unmodelled variance, the chance test, the transform's
covariance against the joined cloud, and independent evidence that must agree.

Frames: planar, x right, y up; T maps the source (local) map into the target (common) map."""

import numpy as np
import pytest
from scipy.special import comb
from scipy.stats import chi2

from mrslam_core.fusion.acceptance import (
    Evidence,
    JoinGate,
    absorbable,
    chi2_align,
    marginal_landmarks,
    pose_jacobian_transform,
    unmodelled_variance,
)
from mrslam_core.fusion.alignment import apply_transform, transform_information_covariance
from mrslam_core.fusion.config import FusionConfig
from mrslam_core.fusion.maps import LandmarkMap
from mrslam_core.slam.config import FilterConfig
from mrslam_core.slam.filter import MultiRobotFastSLAM

T = np.array([1.0, -2.0, 0.7])
SIGMA = 0.05  # per coordinate, each map


def offset_maps(eps: float, n_extra: int = 0):
    """Four source points (±3, 0), (0, ±3) around the origin, the target T(source) moved by ``eps``
    [m] along R·(0, 1), R·(0, 1), R·(0, −1), R·(0, −1): the residuals sum to zero and have no
    torque, so the least-squares fit is exactly T and each residual has length eps (and no pair's
    separation changes by more than √2·eps); ``n_extra`` exact points further out."""
    src = np.array([[3.0, 0.0], [-3.0, 0.0], [0.0, 3.0], [0.0, -3.0]])
    src = np.vstack([src, np.array([[6.0, 6.0 + k] for k in range(n_extra)]).reshape(-1, 2)])
    dst = apply_transform(T, src)
    c, s = np.cos(T[2]), np.sin(T[2])
    dst[:4] += eps * np.array([[-s, c], [-s, c], [s, -c], [s, -c]])
    cov = np.broadcast_to(np.eye(2) * SIGMA**2, (len(src), 2, 2))
    return LandmarkMap.from_arrays(dst, cov), LandmarkMap.from_arrays(src, cov)


def test_residuals_the_maps_explain_leave_no_unmodelled_variance():
    """Each of the 4 residuals of length eps with eps² = 2σ², i.e. σ² per coordinate against the
    covariance 2σ² the two maps give: u = 0, χ² = 4·eps²/(2σ²) = 4 exactly with dof 2·4 − 3 = 5,
    and Cov T is the landmark-covariance form (reduced χ² below 1)."""
    eps = np.sqrt(2 * SIGMA**2)
    tgt, src = offset_maps(eps)
    al = chi2_align(tgt, src, FusionConfig(), np.column_stack([np.arange(4), np.arange(4)]))
    np.testing.assert_allclose(al.transform, T, atol=1e-9)
    assert al.unmodelled_sigma == 0.0 and al.inliers.size == 4 and al.dof == 5 and al.consistent
    assert al.chi2 == pytest.approx(4.0, rel=1e-9)
    np.testing.assert_allclose(al.cov, transform_information_covariance(T, src.means, src.covs, tgt.covs), rtol=1e-6, atol=1e-15)


def test_a_disagreement_every_pair_shares_is_an_unmodelled_variance():
    """The same with eps² = 8σ² (χ² 16 on the maps' covariances, above χ²₅(0.99) = 15.09): the
    residuals hold 4σ² per coordinate, so the most likely shared variance is u² = 4σ² − 2σ² = 2σ².
    With it every pair is an inlier, χ² = 4·8σ²/4σ² = 8 with dof 5, and Cov T is the information
    form with S + u²I, times the reduced χ² 8/5."""
    assert chi2.ppf(0.99, 5) == pytest.approx(15.086, abs=1e-3)
    eps = np.sqrt(8 * SIGMA**2)
    tgt, src = offset_maps(eps)
    al = chi2_align(tgt, src, FusionConfig(), np.column_stack([np.arange(4), np.arange(4)]))
    np.testing.assert_allclose(al.transform, T, atol=1e-9)
    assert al.unmodelled_sigma**2 == pytest.approx(2 * SIGMA**2, rel=1e-2)
    assert al.inliers.size == 4 and al.dof == 5 and al.consistent
    assert al.chi2 == pytest.approx(8.0, rel=1e-2)
    u2 = al.unmodelled_sigma**2
    info_cov = transform_information_covariance(T, src.means, src.covs + 0.5 * u2 * np.eye(3), tgt.covs + 0.5 * u2 * np.eye(3))
    np.testing.assert_allclose(al.cov, info_cov * al.chi2 / 5, rtol=1e-6, atol=1e-15)


def test_the_unmodelled_variance_is_recovered_from_heterogeneous_covariances():
    """400 residuals ~ N(0, Sᵢ + u²I), Sᵢ's σ spread over 1–80 mm (a young stereo map), u = 0.05 m,
    10 % of them wrong matches (uniform over 20 × 20 m): u is recovered within 10 %, and with u = 0
    (residuals inside their covariances) it is 0."""
    rng = np.random.default_rng(3)
    n, area = 400, 400.0
    sig = np.exp(rng.uniform(np.log(0.001), np.log(0.08), n))
    cov = np.einsum("n,ij->nij", sig**2, np.eye(2))
    wrong = rng.random(n) < 0.1
    res = rng.standard_normal((n, 2)) * np.sqrt(sig**2 + 0.05**2)[:, None]
    res[wrong] = rng.uniform(-10, 10, (int(wrong.sum()), 2))
    assert np.sqrt(unmodelled_variance(res, cov, area)) == pytest.approx(0.05, rel=0.1)  # 0.047
    res = rng.standard_normal((n, 2)) * sig[:, None] * 0.9
    res[wrong] = rng.uniform(-10, 10, (int(wrong.sum()), 2))
    assert unmodelled_variance(res, cov, area) == 0.0


def test_a_wrong_match_falls_outside_its_gate():
    tgt, src = offset_maps(0.0, n_extra=2)
    matches = np.column_stack([np.arange(6), np.arange(6)])
    matches[5, 0] = 0  # source 5 matched to target 0, 8 m away
    al = chi2_align(tgt, src, FusionConfig(), matches)
    assert al.inliers.tolist() == [0, 1, 2, 3, 4] and al.consistent
    np.testing.assert_allclose(al.transform, T, atol=1e-9)


def test_a_small_inlier_set_is_explainable_by_chance():
    """Three matches in a 6 × 6 m map with σ = 0.5 m: a wrong transform puts the third inside its
    gate with q = π·χ²₂(0.99)·2σ²/36, and any of the C(3, 2) pairs could have been chosen:
    chance 3q > 0.01, refused; with σ = 0.02 m it passes."""
    src = np.array([[3.0, 0.0], [-3.0, 0.0], [0.0, 3.0]])
    for sigma, passes in ((0.5, False), (0.02, True)):
        cov = np.broadcast_to(np.eye(2) * sigma**2, (3, 2, 2))
        tgt_map = LandmarkMap.from_arrays(apply_transform(T, src), cov)
        al = chi2_align(tgt_map, LandmarkMap.from_arrays(src, cov), FusionConfig(), np.column_stack([np.arange(3)] * 2))
        ext = np.ptp(tgt_map.means[:, :2], axis=0)
        q = np.pi * chi2.ppf(0.99, 2) * 2 * sigma**2 / (ext[0] * ext[1])
        assert al.chance == pytest.approx(min(1.0, comb(3, 2) * q), rel=1e-9)
        assert al.consistent is passes
        if not passes:
            assert "explainable by chance" in al.reason


def test_absorbable_is_the_expected_mahalanobis_load():
    """tr(P_ref⁻¹ P_T) for diagonal matrices: Σ P_T,ii / P_ref,ii; and P_T = J_T Cov T J_Tᵀ with
    J_T = [I₂ | ∂R/∂θ·x; 0 0 1] at the robot's local position."""
    assert absorbable(np.diag([0.02, 0.01, 0.001]), np.diag([0.01, 0.01, 0.001])) == pytest.approx(4.0)
    jt = pose_jacobian_transform(np.array([0.0, 0.0, 0.0]), np.array([2.0, 0.0, 0.0]))
    np.testing.assert_allclose(jt, [[1, 0, 0], [0, 1, 2.0], [0, 0, 1]])
    # a heading error of σ 0.01 rad 2 m away is 0.02 m of lateral error
    p_t = jt @ np.diag([0.0, 0.0, 1e-4]) @ jt.T
    assert p_t[1, 1] == pytest.approx(4e-4)


def test_marginal_landmarks_add_the_particles_spread():
    slam = MultiRobotFastSLAM(FilterConfig(num_particles=2, seed=0), ["a"], np.zeros((1, 3)))
    mean = np.array([[[0.0, 0.0, 0.0]], [[2.0, 0.0, 0.0]]])
    cov = np.broadcast_to(np.eye(3) * 0.01, (2, 1, 3, 3)).copy()
    slam.insert_landmarks(mean, cov, np.ones((2, 1), bool), np.zeros((1, 0), np.float32))
    slam.log_w = np.log(np.array([0.25, 0.75]))
    mu, sigma = marginal_landmarks(slam, np.array([0]))
    np.testing.assert_allclose(mu, [[1.5, 0.0, 0.0]])
    np.testing.assert_allclose(sigma[0], np.diag([0.01 + 0.25 * 0.75 * 4, 0.01, 0.01]), atol=1e-7)


def ev(t, cov=np.eye(3) * 0.01, strong=False, source="sighting"):
    return Evidence(np.asarray(t, float), cov, source, strong, source)


def test_the_gate_joins_on_independent_agreeing_evidence_only():
    gate = JoinGate.from_config(FusionConfig())
    assert gate.threshold == pytest.approx(chi2.ppf(0.99, 3))
    # a weak alignment waits; another alignment of the same maps never confirms it
    assert gate.offer("b", 10.0, ev([1, 0, 0], source="alignment")) is None
    assert gate.offer("b", 15.0, ev([1, 0, 0], source="alignment")) is None
    # a sighting that agrees (distance² 0.1²/0.02 = 0.5) confirms it
    s = ev([1.1, 0, 0])
    assert gate.offer("b", 16.0, s) is s and "b" not in gate.held
    # a strong alignment alone joins; one contradicted by a held sighting waits
    strong = ev([1, 0, 0], strong=True, source="alignment")
    assert gate.offer("c", 1.0, strong) is strong
    assert gate.offer("d", 1.0, ev([3, 0, 0])) is None
    assert gate.offer("d", 2.0, strong) is None and "disagrees" in gate.log["d"][-1]
    # held evidence expires after the window
    assert gate.offer("d", 20.0, strong) is strong
