"""Wheel odometry with systematic and random errors, vectorised over robots.

The true motion of one physics step (from ground truth) is turned into wheel distances, corrupted
by the errors of :class:`~mrslam_core.sim.config.OdometryNoiseConfig` and integrated in each
robot's odom frame (x forward, y left at the start pose, REP-105).
"""

from __future__ import annotations

import numpy as np

from mrslam_core.geometry.se2 import wrap_angle
from mrslam_core.sim.config import OdometryNoiseConfig


def true_increment(prev: np.ndarray, now: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Arc length and heading change between two ground-truth poses.

    Args:
        prev, now: (N, 3) poses (x, y, θ) in the map [m, m, rad].

    Returns:
        ds: (N,) signed distance along the mid-step heading [m].
        dth: (N,) heading change wrapped to (−π, π] [rad].
    """
    dth = wrap_angle(now[:, 2] - prev[:, 2])
    mid = prev[:, 2] + dth / 2
    d = now[:, :2] - prev[:, :2]
    return np.cos(mid) * d[:, 0] + np.sin(mid) * d[:, 1], dth


def noisy_increment(ds: np.ndarray, dth: np.ndarray, cfg: OdometryNoiseConfig, track: float,
                    rng: np.random.Generator) -> np.ndarray:
    """What the wheel encoders report for a true step (ds, dth), as a base_link increment.

    Args:
        ds, dth: (N,) true arc length [m] and heading change [rad].
        cfg: the error model.
        track: true wheel track [m].
        rng: draws 3·N standard normals (always, so seeded runs stay aligned).

    Returns:
        (N, 3) increment (dx, dy, dθ) in base_link at the start of the step [m, m, rad].
    """
    left = (ds - dth * track / 2) * (1 + cfg.scale_error_left)
    right = (ds + dth * track / 2) * (1 + cfg.scale_error_right)
    ds_o = (left + right) / 2
    dth_o = (right - left) / (track * (1 + cfg.track_error))
    z = rng.standard_normal((3, ds.shape[0]))
    dist, turn = np.abs(ds), np.abs(dth)
    trans_sd = np.sqrt(cfg.translation_var_per_m * dist)
    dth_o = dth_o + z[2] * np.sqrt(cfg.heading_var_per_m * dist + cfg.heading_var_per_rad * turn)
    half = dth_o / 2
    along = ds_o + z[0] * trans_sd
    across = z[1] * trans_sd
    return np.stack([along * np.cos(half) - across * np.sin(half),
                     along * np.sin(half) + across * np.cos(half), dth_o], axis=1)

