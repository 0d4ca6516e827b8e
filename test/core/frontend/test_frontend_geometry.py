"""Exact answers: rectified rig parameters, triangulation and covariance moved into base_link."""

from __future__ import annotations

import numpy as np
import pytest

from mrslam_core.frontend import CameraCalibration, CameraModelError, Frontend, FrontendConfig, StereoRig


def rot_y(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def test_rig_from_camera_info_uses_p_and_undoes_r():
    k = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    p_left = np.array([[480.0, 0, 310, 0], [0, 480, 235, 0], [0, 0, 1, 0]])
    p_right = p_left.copy()
    p_right[0, 3] = -480.0 * 0.2
    r = rot_y(0.1)
    left = CameraCalibration(640, 480, k, np.zeros(5), r, p_left)
    right = CameraCalibration(640, 480, k, np.zeros(5), r.T, p_right)
    t_base_cam = np.eye(4)
    t_base_cam[:3, 3] = (1.0, 2.0, 3.0)
    rig = StereoRig(left, right, t_base_cam)
    assert (rig.f, rig.cx, rig.cy) == (480.0, 310.0, 235.0)
    assert rig.baseline == pytest.approx(0.2, abs=1e-12)
    assert rig.needs_rectification
    # a point on the rectified optical axis lies along Rᵀ·(0, 0, 1) in the raw camera frame
    expected = np.eye(4)
    expected[:3, :3] = r.T
    expected[:3, 3] = (1.0, 2.0, 3.0)
    np.testing.assert_allclose(rig.t_base_rect, expected, atol=1e-15)


def test_observation_in_base_link_exact(small_rig, textured):
    """A fronto-parallel plane: right image = left shifted by 12 px; 3 frames -> exact points.

    Rig: f = 300, cx = 160, cy = 120, b = 0.12; camera 0.1 m ahead, 0.5 m up, looking along x.
    Disparity 12 px -> depth f·b/d = 3 m; pixel (r, c) -> optical (b(c−cx)/d, b(r−cy)/d, 3),
    base_link (0.1 + 3, −b(c−cx)/d, 0.5 − b(r−cy)/d).
    """
    cfg = FrontendConfig(max_disparity=32, obstacle_source="features")
    fe = Frontend(small_rig, cfg)
    left = textured(240, 340, seed=3)
    right = left[:, 12:332]  # right pixel (r, c − 12) shows left pixel (r, c)
    left = left[:, 0:320]
    obs = None
    for i in range(3):
        obs, _ = fe.step(np.ascontiguousarray(left), np.ascontiguousarray(right), 1000 + i)
    assert not fe.drops
    assert len(obs) == cfg.max_observations
    frame = fe.last_frame
    err = np.abs(frame.disparity - 12.0)
    assert np.median(err) <= 0.06 and err.max() <= 0.3  # parabola sub-pixel fit of 1 − ZNCC (0.052)
    # observations are a subset of the frame's points: their base_link values by hand
    sel = np.isin(frame.track_ids, obs.track_ids)
    order = np.argsort(frame.track_ids[sel])
    (c, r), d = frame.xy[sel][order].T, frame.disparity[sel][order]
    b, f = 0.12, 300.0
    xo, yo, zo = b * (c - 160) / d, b * (r - 120) / d, f * b / d
    expected = np.stack([0.1 + zo, -xo, 0.5 - yo], axis=1)
    got = obs.z[np.argsort(obs.track_ids)]
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got[:, 0], 3.1, atol=0.08)  # 3 m ahead of a camera 0.1 m ahead
    # covariance: J = ∂(xo, yo, zo)/∂(d, r, c), R = J·diag(1, 10², 10²)·Jᵀ, then
    # base (x, y, z) = (zo, −xo, −yo)
    jac = np.zeros((len(d), 3, 3))
    jac[:, 0, 0] = -b * (c - 160) / d**2
    jac[:, 0, 2] = b / d
    jac[:, 1, 0] = -b * (r - 120) / d**2
    jac[:, 1, 1] = b / d
    jac[:, 2, 0] = -f * b / d**2
    cov_opt = jac @ np.diag([1.0, 100.0, 100.0]) @ jac.transpose(0, 2, 1)
    perm = np.array([[0.0, 0, 1], [-1, 0, 0], [0, -1, 0]])
    np.testing.assert_allclose(obs.cov[np.argsort(obs.track_ids)], perm @ cov_opt @ perm.T,
                               rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(K=np.zeros((3, 3))), "zero focal"),
        (dict(P=np.zeros((3, 4))), "zero focal"),
        (dict(width=0), "empty"),
        (dict(R=np.ones((3, 3))), "not a rotation"),
        (dict(D=[np.nan, 0, 0, 0]), "non-finite"),
        (dict(distortion_model="kannala"), "unsupported"),
    ],
)
def test_bad_camera_info_raises(change, message):
    k = np.array([[300.0, 0, 160], [0, 300, 120], [0, 0, 1]])
    base = dict(width=320, height=240, K=k, D=np.zeros(5), R=np.eye(3), P=np.hstack([k, np.zeros((3, 1))]))
    base.update(change)
    with pytest.raises(CameraModelError, match=message):
        CameraCalibration(**base)


def test_right_camera_on_the_wrong_side_raises():
    k = np.array([[300.0, 0, 160], [0, 300, 120], [0, 0, 1]])
    p = np.hstack([k, np.zeros((3, 1))])
    cam = CameraCalibration(320, 240, k, np.zeros(5), np.eye(3), p)
    p_bad = p.copy()
    p_bad[0, 3] = +300 * 0.1
    with pytest.raises(CameraModelError, match="baseline"):
        StereoRig(cam, CameraCalibration(320, 240, k, np.zeros(5), np.eye(3), p_bad), np.eye(4))
    with pytest.raises(CameraModelError, match="sizes differ"):
        StereoRig(cam, CameraCalibration(640, 240, k, np.zeros(5), np.eye(3), p), np.eye(4))
