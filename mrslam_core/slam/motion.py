"""Sampling the odometry motion model for all particles at once."""

from __future__ import annotations

import numpy as np

from mrslam_core.geometry.se2 import compose, wrap_angle
from mrslam_core.slam.config import MotionConfig


def decompose(delta: np.ndarray) -> tuple[float, float, float]:
    """Relative motion (dx, dy, dθ) in the previous base frame -> (rot1, trans, rot2).

    A robot driving backwards gets a negative ``trans`` and a small ``rot1`` instead of a rot1
    near ±π, so the rotation noise does not explode for reversing.
    """
    dx, dy, dth = (float(v) for v in delta)
    trans = float(np.hypot(dx, dy))
    if trans < 1e-9:
        return 0.0, 0.0, float(wrap_angle(dth))
    rot1 = float(np.arctan2(dy, dx))
    if abs(rot1) > np.pi / 2:
        rot1 = float(wrap_angle(rot1 + np.pi))
        trans = -trans
    return rot1, trans, float(wrap_angle(dth - rot1))


def sample_motion(
    poses: np.ndarray, delta: np.ndarray, cfg: MotionConfig, rng: np.random.Generator
) -> np.ndarray:
    """Move poses (M, 3) by the odometry delta (3,) with sampled noise; returns new (M, 3).

    Args:
        poses: particle poses of one robot in the map frame (x [m], y [m], θ [rad]).
        delta: relative motion between two odometry readings, in the earlier base frame.
        cfg: noise parameters.
        rng: random generator.
    """
    rot1, trans, rot2 = decompose(delta)
    m = poses.shape[0]
    s_rot1 = np.sqrt(cfg.alpha1 * rot1**2 + cfg.alpha2 * trans**2)
    s_trans = np.sqrt(cfg.alpha3 * trans**2 + cfg.alpha4 * (rot1**2 + rot2**2))
    s_rot2 = np.sqrt(cfg.alpha1 * rot2**2 + cfg.alpha2 * trans**2)
    noise = rng.standard_normal((m, 3))
    r1 = rot1 + s_rot1 * noise[:, 0]
    tr = trans + s_trans * noise[:, 1]
    r2 = rot2 + s_rot2 * noise[:, 2]
    step = np.stack([tr * np.cos(r1), tr * np.sin(r1), r1 + r2], axis=-1)
    if cfg.min_sigma_xy > 0 or cfg.min_sigma_theta > 0:
        floor = rng.standard_normal((m, 3)) * np.array(
            [cfg.min_sigma_xy, cfg.min_sigma_xy, cfg.min_sigma_theta]
        )
        step += floor
    return compose(poses, step)
