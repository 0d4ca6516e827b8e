"""Sampling the odometry motion model for all particles at once."""

from __future__ import annotations

import numpy as np

from mrslam_core.geometry.se2 import compose, wrap_angle
from mrslam_core.slam.config import MotionConfig

#: below this motion [m] and turn [rad] over an update the odometry reports none (floating-point
#: round-off of identical poses)
STILL = 1e-9


def reports_motion(delta: np.ndarray) -> np.ndarray:
    """Whether odometry deltas (..., 3) (dx [m], dy [m], dθ [rad]) report any motion: (...) bool,
    True where a component exceeds :data:`STILL`. The random walk accrues only over these."""
    return np.any(np.abs(np.asarray(delta, float)) > STILL, axis=-1)


def decompose(delta: np.ndarray, min_translation: float = 0.0) -> tuple[float, float, float]:
    """Relative motion (dx, dy, dθ) in the previous base frame -> (rot1, trans, rot2).

    A robot driving backwards gets a negative ``trans`` and a small ``rot1`` instead of a rot1
    near ±π, so the rotation noise does not explode for reversing. Below ``min_translation`` [m]
    the direction of travel is meaningless (wheel jitter of a turning or still robot), so rot1 is
    0 and the whole rotation goes to rot2, as in ROS amcl's odometry model.
    """
    dx, dy, dth = (float(v) for v in delta)
    trans = float(np.hypot(dx, dy))
    if trans < max(min_translation, 1e-9):
        return 0.0, trans, float(wrap_angle(dth))
    rot1 = float(np.arctan2(dy, dx))
    if abs(rot1) > np.pi / 2:
        rot1 = float(wrap_angle(rot1 + np.pi))
        trans = -trans
    return rot1, trans, float(wrap_angle(dth - rot1))


def sample_motion(
    poses: np.ndarray, delta: np.ndarray, cfg: MotionConfig, rng: np.random.Generator, dt: float = 0.0
) -> np.ndarray:
    """Move poses (M, 3) by the odometry delta (3,) with sampled noise; returns new (M, 3).

    Args:
        poses: particle poses of one robot in the map frame (x [m], y [m], θ [rad]).
        delta: relative motion between two odometry readings, in the earlier base frame.
        cfg: noise parameters.
        rng: random generator.
        dt: time the motion took [s] (scales the random-walk part of the noise).
    """
    rot1, trans, rot2 = decompose(delta, cfg.min_translation)
    m = poses.shape[0]
    s_rot1 = np.sqrt(cfg.alpha1 * rot1**2 + cfg.alpha2 * trans**2)
    s_trans = np.sqrt(cfg.alpha3 * trans**2 + cfg.alpha4 * (rot1**2 + rot2**2))
    s_rot2 = np.sqrt(cfg.alpha1 * rot2**2 + cfg.alpha2 * trans**2)
    noise = rng.standard_normal((m, 3))
    r1 = rot1 + s_rot1 * noise[:, 0]
    tr = trans + s_trans * noise[:, 1]
    r2 = rot2 + s_rot2 * noise[:, 2]
    step = np.stack([tr * np.cos(r1), tr * np.sin(r1), r1 + r2], axis=-1)
    sd = np.sqrt(_walk_variance(cfg, trans, rot1 + rot2, dt if reports_motion(delta) else 0.0))
    if sd.any():
        step += rng.standard_normal((m, 3)) * sd
    return compose(poses, step)


def _walk_variance(cfg: MotionConfig, trans: float, turn: float, dt: float) -> np.ndarray:
    """Variances (3,) of the noise added in the robot frame on top of the (rot1, trans, rot2)
    model: time random walk plus distance- and angle-proportional terms.

    ``dt`` [s] is the time the robot moved: the random walk models how the executed motion departs
    from the reported one while the robot moves, so the callers pass 0 for an update whose
    odometry reports no motion (:func:`reports_motion`; a zero-velocity update).
    """
    t = max(dt, 0.0)
    d, a = abs(trans), abs(float(wrap_angle(turn)))
    var_xy = cfg.sigma_xy_rw**2 * t + cfg.var_xy_per_m * d
    return np.array([var_xy, var_xy, cfg.sigma_theta_rw**2 * t + cfg.var_theta_per_m * d + cfg.var_theta_per_rad * a])


def predict_motion(
    poses: np.ndarray, delta: np.ndarray, cfg: MotionConfig, dt: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Noise-free motion and its Gaussian noise, linearised (the FastSLAM 2.0 prior).

    Args:
        poses: (M, 3) poses before the motion, map frame.
        delta: (3,) odometry motion in the earlier base frame.
        cfg: noise parameters (the same as :func:`sample_motion` draws from).
        dt: duration of the motion [s].

    Returns:
        (x̂ (M, 3) = poses ⊕ delta, P (M, 3, 3) covariance of the sampled pose around x̂).
    """
    rot1, trans, rot2 = decompose(delta, cfg.min_translation)
    var = np.array([
        cfg.alpha1 * rot1**2 + cfg.alpha2 * trans**2,
        cfg.alpha3 * trans**2 + cfg.alpha4 * (rot1**2 + rot2**2),
        cfg.alpha1 * rot2**2 + cfg.alpha2 * trans**2,
    ])
    th = poses[:, 2] + rot1
    c, s = np.cos(th), np.sin(th)
    jac = np.zeros((poses.shape[0], 3, 3))  # ∂(x, y, θ)/∂(rot1, trans, rot2)
    jac[:, 0, 0] = -trans * s
    jac[:, 1, 0] = trans * c
    jac[:, 2, 0] = 1.0
    jac[:, 0, 1] = c
    jac[:, 1, 1] = s
    jac[:, 2, 2] = 1.0
    cov = (jac * var[None, None, :]) @ np.swapaxes(jac, 1, 2)
    cov += np.diag(_walk_variance(cfg, trans, rot1 + rot2, dt if reports_motion(delta) else 0.0) + 1e-12)
    return compose(poses, np.array([trans * np.cos(rot1), trans * np.sin(rot1), rot1 + rot2])), cov
