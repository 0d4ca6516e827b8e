"""Observation models: Jacobians against finite differences, EKF against a hand computation,
and the stereo model's map-frame fast path against the generic EKF."""

import numpy as np
import pytest

from mrslam_core.slam.models import ObservationModel, RangeBearingModel, StereoPointModel, make_model


def _num_jac(fun, x, eps=1e-6):
    return np.column_stack([(fun(x + e) - fun(x - e)) / (2 * eps) for e in np.eye(len(x)) * eps])


@pytest.mark.parametrize("model", [StereoPointModel(), RangeBearingModel()])
def test_jacobians_and_inverse(model):
    pose = np.array([0.5, -1.0, 0.7])
    lm = np.array([3.0, 1.0, 1.2])[: model.dim]
    zhat, g = model.predict(pose, lm)
    np.testing.assert_allclose(g, _num_jac(lambda l: model.predict(pose, l)[0], lm), rtol=1e-6, atol=1e-8)
    hx = model.pose_jacobian(pose, lm)
    np.testing.assert_allclose(hx, _num_jac(lambda p: model.predict(p, lm)[0], pose), rtol=1e-6, atol=1e-8)
    back, ginv = model.inverse(pose, zhat)
    np.testing.assert_allclose(back, lm, atol=1e-12)
    np.testing.assert_allclose(g @ ginv, np.eye(model.dim), atol=1e-12)


def test_ekf_update_hand_computed_range_bearing():
    # robot at the origin facing +x, landmark at (2, 0): G = [[1, 0], [0, 0.5]]
    m = RangeBearingModel()
    pose = np.zeros((1, 3))
    mu = np.array([[2.0, 0.0]])
    sig = np.eye(2)[None] * 0.04
    r = np.diag([0.01, 0.0025])[None]
    z = np.array([[2.1, 0.05]])
    new_mu, new_sig, maha, _ = m.update(pose, z, r, mu, sig)
    # Z = G Σ Gᵀ + R = diag(0.05, 0.0125); K = Σ Gᵀ Z⁻¹ = diag(0.8, 1.6); ν = (0.1, 0.05)
    np.testing.assert_allclose(new_mu, [[2.08, 0.08]], atol=1e-12)
    np.testing.assert_allclose(new_sig, np.diag([0.008, 0.008])[None], atol=1e-12)
    assert maha[0] == pytest.approx(0.1**2 / 0.05 + 0.05**2 / 0.0125)


def test_stereo_fast_path_equals_generic_ekf():
    rng = np.random.default_rng(3)
    fast = StereoPointModel()
    poses = np.column_stack([rng.uniform(-1, 1, (20, 2)), rng.uniform(-3, 3, 20)])
    mu = rng.uniform(-5, 5, (20, 3))
    a = rng.standard_normal((20, 3, 3))
    sig = a @ a.transpose(0, 2, 1) * 0.01 + 0.01 * np.eye(3)
    b = rng.standard_normal((20, 3, 3))
    r = b @ b.transpose(0, 2, 1) * 0.01 + 0.01 * np.eye(3)
    z = fast.predict(poses, mu)[0] + 0.1 * rng.standard_normal((20, 3))
    for got, want in zip(fast.update(poses, z, r, mu, sig), ObservationModel.update(fast, poses, z, r, mu, sig)):
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)
    for got, want in zip(fast.score(poses, z, r, mu, sig), ObservationModel.score(fast, poses, z, r, mu, sig)):
        np.testing.assert_allclose(got, want, rtol=1e-9)
    lm, cov = fast.new_landmark(poses, z, r)
    lm2, cov2 = ObservationModel.new_landmark(fast, poses, z, r)
    np.testing.assert_allclose(cov, cov2, atol=1e-12)


def test_new_landmark_covariance_is_inverse_information():
    # corrected line 36 of Alg. 1: Σ = (Gᵀ R⁻¹ G)⁻¹ = G⁻¹ R G⁻ᵀ
    m = RangeBearingModel()
    pose = np.array([0.0, 0.0, 0.3])
    z = np.array([3.0, 0.4])
    r = np.diag([0.04, 0.001])
    lm, cov = m.new_landmark(pose, z, r)
    _, g = m.predict(pose, lm)
    np.testing.assert_allclose(cov, np.linalg.inv(g.T @ np.linalg.inv(r) @ g), rtol=1e-9)


def test_unknown_model_name():
    with pytest.raises(ValueError, match="unknown observation model"):
        make_model("lidar")


def test_stereo_score_on_candidate_pairs_equals_generic():
    # the filter's call: poses (M, 1, 3), observations (1, B, ·), V pairs picking observation index[v]
    rng = np.random.default_rng(4)
    fast = StereoPointModel()
    m, b, v = 7, 5, 9
    poses = np.column_stack([rng.uniform(-1, 1, (m, 2)), rng.uniform(-3, 3, m)])[:, None, :]
    z = rng.uniform(-3, 3, (1, b, 3))
    a = rng.standard_normal((1, b, 3, 3))
    r = a @ np.swapaxes(a, -1, -2) * 0.01 + 0.01 * np.eye(3)
    index = rng.integers(0, b, v)
    mu = rng.uniform(-3, 3, (m, v, 3)).astype(np.float32)
    c = rng.standard_normal((m, v, 3, 3))
    sig = (c @ np.swapaxes(c, -1, -2) * 0.01 + 0.01 * np.eye(3)).astype(np.float32)
    got = fast.score(poses, z, r, mu, sig, index=index)
    want = ObservationModel.score(fast, np.broadcast_to(poses, (m, v, 3)), z[:, index], r[:, index], mu, sig)
    for g, w in zip(got, want):
        np.testing.assert_allclose(g, w, rtol=1e-6)
