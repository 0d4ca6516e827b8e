"""Wheel-odometry error model (002 Table I kind), checked on many seeded robots at once."""

import numpy as np
import pytest

from mrslam_core.geometry.se2 import compose
from mrslam_core.sim.config import OdometryNoiseConfig
from mrslam_core.sim.odometry import noisy_increment, true_increment

ZERO = OdometryNoiseConfig(scale_error_left=0, scale_error_right=0, track_error=0, translation_var_per_m=0,
                           heading_var_per_m=0, heading_var_per_rad=0)


def drive(cfg, ds, dth, steps, n=4000, seed=7):
    """n robots each integrate ``steps`` equal true steps (ds, dth) from the origin."""
    rng = np.random.default_rng(seed)
    pose = np.zeros((n, 3))
    for _ in range(steps):
        pose = compose(pose, noisy_increment(np.full(n, ds), np.full(n, dth), cfg, 0.33, rng))
    return pose


def test_translation_noise_grows_with_distance():
    k = 1.25e-3
    cfg = OdometryNoiseConfig(**{**ZERO.__dict__, "translation_var_per_m": k})
    pose = drive(cfg, 0.01, 0.0, 200)  # 2 m straight; physics steps of 1 cm
    err = pose[:, :2] - [2.0, 0.0]
    np.testing.assert_allclose(err.std(axis=0), np.sqrt(k * 2.0), rtol=0.05)  # 0.05 m along and across
    assert np.all(np.abs(err.mean(axis=0)) < 4 * np.sqrt(k * 2.0 / 4000))
    assert np.all(pose[:, 2] == 0)


def test_heading_noise_per_metre_and_per_radian():
    kd, kr = 5.483e-3, 1.745e-3
    cfg = OdometryNoiseConfig(**{**ZERO.__dict__, "heading_var_per_m": kd})
    assert drive(cfg, 0.01, 0.0, 300)[:, 2].std() == pytest.approx(np.sqrt(kd * 3.0), rel=0.05)
    cfg = OdometryNoiseConfig(**{**ZERO.__dict__, "heading_var_per_rad": kr})
    turned = drive(cfg, 0.0, 0.02, 100)[:, 2] - 2.0  # on the spot, 2 rad
    assert turned.std() == pytest.approx(np.sqrt(kr * 2.0), rel=0.05)
    # the statistics do not depend on the step length (variance proportional to the motion)
    coarse = drive(cfg, 0.0, 0.1, 20)[:, 2] - 2.0
    assert coarse.std() == pytest.approx(np.sqrt(kr * 2.0), rel=0.05)


def test_systematic_errors_are_exact():
    cfg = OdometryNoiseConfig(**{**ZERO.__dict__, "scale_error_left": -0.01, "scale_error_right": 0.01})
    pose = drive(cfg, 0.01, 0.0, 100, n=1)  # 1 m straight: the right wheel runs 2 % further
    dth = 0.02 * 0.01 / 0.33  # per step: (1.01 − 0.99)·ds / track
    assert pose[0, 2] == pytest.approx(100 * dth, rel=1e-9)
    assert pose[0, 0] == pytest.approx(np.sum(0.01 * np.cos((np.arange(100) + 0.5) * dth)), rel=1e-9)


def test_true_increment_of_an_arc():
    prev = np.array([[1.0, 2.0, 0.3]])
    r, a = 2.0, 0.1  # radius, angle
    now = np.array([[1.0 + r * (np.sin(0.3 + a) - np.sin(0.3)), 2.0 - r * (np.cos(0.3 + a) - np.cos(0.3)), 0.3 + a]])
    ds, dth = true_increment(prev, now)
    assert dth[0] == pytest.approx(a) and ds[0] == pytest.approx(2 * r * np.sin(a / 2), rel=1e-12)  # the chord
