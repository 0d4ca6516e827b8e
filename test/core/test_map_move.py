"""The map check's decision (mrslam_core.pipelines.central.map_move): the frame's likelihood in
closed form, and lost-or-not by posterior odds, with look-alikes, outside the lost prior's
support and at the exact odds."""

from __future__ import annotations

import numpy as np
import pytest

from mrslam_core.geometry.se2 import wrap_angle
from mrslam_core.pipelines.central.map_move import candidate_pairs, frame_log_likelihood, lost_or_not, refine

FLOOR = 0.03
ETA = 0.5
LOG_AREA = float(np.log(50.0))


def _world_of(pose: np.ndarray, frame: np.ndarray) -> np.ndarray:
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return frame[:, :2] @ np.array([[c, s], [-s, c]]) + pose[:2]


def _scene(n: int = 30, seed: int = 0):
    """n frame points 1-4 m ahead, 1 cm covariance, random 8-D descriptors."""
    rng = np.random.default_rng(seed)
    frame = np.column_stack([rng.uniform(1, 4, n), rng.uniform(-2, 2, n), rng.uniform(0, 1, n)])
    covs = np.tile(np.eye(3) * 1e-4, (n, 1, 1))
    desc = rng.uniform(0, 1, (n, 8))
    return frame, covs, desc


def _likelihood(frame, covs, pairs, lm_xy):
    """log_lik over (M, S, 3) poses for one particle's landmarks lm_xy (P, 2) at the pairs."""
    p = len(pairs)
    mean = np.zeros((1, p, 3))
    mean[0, :, :2] = lm_xy
    cov = np.tile(np.eye(3) * 4e-4, (1, p, 1, 1))
    held = np.ones((1, p), bool)

    def log_lik(x):
        return frame_log_likelihood(x, frame, covs, pairs, mean, cov, held, ETA, LOG_AREA, FLOOR)
    return log_lik


def test_one_point_with_one_candidate_has_the_contaminated_normal_likelihood():
    """Point (2, 0) seen from (1, 1, 90°) lands at (1, 3); its landmark at (1.1, 3.0): the
    residual (-0.1, 0) under C = 4e-4 I + 1e-4 I + 0.03² I."""
    frame = np.array([[2.0, 0.0, 0.0]])
    covs = np.eye(3)[None] * 1e-4
    pose = np.array([[[1.0, 1.0, np.pi / 2]]])
    log_lik = _likelihood(frame, covs, np.array([[0, 0]]), np.array([[1.1, 3.0]]))
    var = 4e-4 + 1e-4 + FLOOR**2
    normal = np.exp(-0.5 * 0.01 / var) / (2 * np.pi * var)
    expected = np.log((1 - ETA) * normal + ETA / np.exp(LOG_AREA))
    assert log_lik(pose)[0, 0] == pytest.approx(expected, rel=1e-12)


def test_a_point_is_explained_by_any_of_its_candidates_alike():
    """A point whose true landmark is its second descriptor candidate scores what it scores with
    the true landmark first: the candidates are summed over, not chosen by descriptor."""
    frame = np.array([[2.0, 0.0, 0.0]])
    covs = np.eye(3)[None] * 1e-4
    pose = np.zeros((1, 1, 3))
    true, other = [2.0, 0.0], [5.0, 5.0]
    a = _likelihood(frame, covs, np.array([[0, 0], [1, 0]]), np.array([true, other]))(pose)
    b = _likelihood(frame, covs, np.array([[1, 0], [0, 0]]), np.array([other, true]))(pose)
    assert a[0, 0] == pytest.approx(b[0, 0], rel=1e-12)


def test_candidate_pairs_are_the_nearest_descriptors_within_the_gate():
    world = np.array([[0.0, 0.0], [0.1, 0.0], [0.0, 0.3], [5.0, 5.0]])
    frame = np.array([[0.05, 0.0], [9.0, 9.0]])
    pairs = candidate_pairs(world, frame, max_sq_dist=0.1**2, k=4)
    assert sorted(pairs[:, 0].tolist()) == [0, 1] and (pairs[:, 1] == 0).all()


def _decide(truth: np.ndarray, filter_pose: np.ndarray, fit: np.ndarray, look_alike_shift: np.ndarray | None,
            lost_probability: float = 0.01, m: int = 200, seed: int = 1):
    """The frame of a robot truly at ``truth``; the older map holds its landmarks (and, with
    ``look_alike_shift`` (2,), a copy of them shifted by it, same descriptors); the filter's
    particles at ``filter_pose`` with 1 cm / 0.3° spread, the alignment at ``fit``."""
    frame, covs, desc = _scene()
    lm = _world_of(truth, frame)
    world_desc = desc
    if look_alike_shift is not None:
        lm = np.vstack([lm, lm + look_alike_shift])
        world_desc = np.vstack([desc, desc])
    pairs = candidate_pairs(world_desc, desc, 1e-9, 4)
    log_lik = _likelihood(frame, covs, pairs, lm[pairs[:, 0]])
    rng = np.random.default_rng(seed)
    poses = filter_pose + rng.normal(0, 1, (m, 3)) * [0.01, 0.01, 0.005]

    def per_particle(x):  # the single particle map is every particle's
        return np.concatenate([log_lik(x[i:i + 1]) for i in range(len(x))])

    spread = np.diag([0.01**2 + FLOOR**2] * 2 + [0.005**2 + 0.015**2])
    fit_cov = np.diag([FLOOR**2] * 2 + [0.015**2])
    local = refine(filter_pose, frame[:, :2], lm, pairs, 0.3)
    return poses, lost_or_not(poses, spread, fit, fit_cov, per_particle, lost_probability, 1.0, 0.5, rng, local)


def test_a_robot_the_map_places_elsewhere_is_lost_in_every_particle():
    """Filter 8.6° and 0.2 m off; the alignment at the truth explains the frame: every particle
    finds it lost and draws its pose from the fit."""
    truth = np.array([3.0, 1.0, 0.4])
    _, res = _decide(truth, truth + [0.2, 0.0, 0.15], truth, None)
    assert res.lost.all() and res.p_lost.min() > 0.999
    err = res.poses - truth
    assert np.abs(err[:, :2]).max() < 0.15 and np.abs(wrap_angle(err[:, 2])).max() < 0.07


def test_a_look_alike_fit_does_not_move_a_robot_that_is_right():
    """The older map holds every landmark twice, 0.6 m apart, with equal descriptors; the
    alignment picked the copy. Both poses explain the frame equally, so the prior decides: the
    robot stays in every particle: the frame's fit near the filter's pose is as good as the
    copy's, and p_lost = εU / (εU + (1 − ε) N(0; 0, P + Σ_T)) = 2.2e-6."""
    truth = np.array([3.0, 1.0, 0.4])
    poses, res = _decide(truth, truth, truth + [0.6, 0.0, 0.0], np.array([0.6, 0.0]))
    assert not res.lost.any() and res.p_lost.max() < 1e-5
    np.testing.assert_array_equal(res.poses, poses)


def test_a_robot_the_look_alike_copy_explains_better_is_moved():
    """The same two copies, but the filter's pose is 0.6 m off the truth (on the copy's side
    reversed): only the alignment explains the frame by the true landmarks and the copy alike,
    while the filter's pose explains it by nothing."""
    truth = np.array([3.0, 1.0, 0.4])
    _, res = _decide(truth, truth + [-0.3, 0.3, 0.0], truth, np.array([0.6, 0.0]))
    assert res.lost.all()


def test_a_fit_beyond_where_a_lost_robot_may_be_is_never_taken():
    """The alignment 1.5 m away (the lost prior reaches 1 m): no particle moves."""
    truth = np.array([3.0, 1.0, 0.4])
    poses, res = _decide(truth, truth + [1.5, 0.0, 0.0], truth, None)
    assert not res.lost.any()
    np.testing.assert_array_equal(res.poses, poses)


def test_the_posterior_odds_are_the_prior_odds_times_the_evidence_ratio():
    """Equal likelihood at the filter's pose and at a fit 0.3 m away: the filter's pose is the
    better mode of "where the filter says", so p_lost is exactly εU / (εU + (1 − ε) N(0; 0,
    P + Σ_T)) with U = 1 / (π · 1² · 2 · 0.5); with the likelihood 20 nats higher at the fit
    (more than the 13.2 its prior density is lower by), the fit is that mode:
    εU e²⁰ / (εU e²⁰ + (1 − ε) N(T − x; 0, P + Σ_T) e²⁰)."""
    poses = np.zeros((1, 3))
    fit = np.array([0.3, 0.0, 0.0])
    spread = np.diag([0.05**2, 0.05**2, 0.02**2])
    fit_cov = np.diag([0.03**2, 0.03**2, 0.015**2])
    eps = 0.01
    res = lost_or_not(poses, spread, fit, fit_cov, lambda x: np.zeros(x.shape[:2]), eps, 1.0, 0.5,
                      np.random.default_rng(0))
    cov = spread + fit_cov
    peak = 1.0 / np.sqrt((2 * np.pi) ** 3 * np.linalg.det(cov))
    u = 1.0 / (np.pi * 2 * 0.5)
    assert res.p_lost[0] == pytest.approx(eps * u / (eps * u + (1 - eps) * peak), rel=1e-9)
    res = lost_or_not(poses, spread, fit, fit_cov, lambda x: np.array([[0.0, 20.0]]), eps, 1.0, 0.5,
                      np.random.default_rng(0))
    at_fit = peak * np.exp(-0.5 * fit @ np.linalg.solve(cov, fit))
    assert res.p_lost[0] == pytest.approx(eps * u / (eps * u + (1 - eps) * at_fit), rel=1e-9)
    assert res.p_lost[0] > 0.5


def test_the_likelihood_is_the_mixture_over_candidates_per_point_at_every_pose():
    """Random frames, poses and particles, some landmarks not held: each (particle, pose) entry
    is Σ_points log((1 − η)/n_i Σ_{held candidates} N(R f + t − l; 0, R C Rᵀ + Σ_l + σ² I) + η/A),
    summed term by term with scipy."""
    from scipy.stats import multivariate_normal

    rng = np.random.default_rng(3)
    m, s, n = 3, 4, 5
    frame = np.column_stack([rng.uniform(1, 3, n), rng.uniform(-1, 1, n), np.zeros(n)])
    a = rng.normal(size=(n, 3, 3)) * 0.05
    covs = a @ a.transpose(0, 2, 1) + 1e-4 * np.eye(3)
    pairs = np.array([[0, 0], [1, 0], [2, 1], [3, 2], [4, 2], [5, 2], [6, 4]])
    poses = rng.uniform(-0.5, 0.5, (m, s, 3))
    lm = rng.uniform(-1, 3, (m, len(pairs), 3))
    b = rng.normal(size=(m, len(pairs), 3, 3)) * 0.05
    lm_cov = b @ b.transpose(0, 1, 3, 2) + 1e-4 * np.eye(3)
    held = rng.random((m, len(pairs))) < 0.7
    got = frame_log_likelihood(poses, frame, covs, pairs, lm, lm_cov, held, ETA, LOG_AREA, FLOOR)
    for i in range(m):
        for j in range(s):
            x, y, th = poses[i, j]
            rot = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
            total = 0.0
            for point in np.unique(pairs[:, 1]):
                mine = np.flatnonzero(pairs[:, 1] == point)
                dens = sum(multivariate_normal.pdf(rot @ frame[point, :2] + [x, y] - lm[i, p, :2],
                                                   cov=rot @ covs[point, :2, :2] @ rot.T + lm_cov[i, p, :2, :2]
                                                   + FLOOR**2 * np.eye(2))
                           for p in mine if held[i, p])
                total += np.log((1 - ETA) / mine.size * dens + ETA / np.exp(LOG_AREA))
            assert got[i, j] == pytest.approx(total, rel=1e-9)


def test_warm_up_loads_the_compiled_likelihood():
    from mrslam_core.pipelines.central.map_move import warm_up
    from mrslam_core.pipelines.central.map_move_kernels import frame_log_likelihood_kernel

    assert warm_up() >= 0.0 and frame_log_likelihood_kernel.signatures
