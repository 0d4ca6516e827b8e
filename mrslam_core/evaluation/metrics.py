"""Trajectory error measures on planar poses (x [m], y [m], θ [rad]).

ATE here is the plain RMSE of position differences at the same timestamps with NO alignment: the
map frame is fixed by the robots' known start poses, so an alignment would hide real errors.
"""

from __future__ import annotations

import numpy as np

from mrslam_core.geometry.se2 import between, wrap_angle


def interpolate_poses(t_query: np.ndarray, t: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Linear interpolation of poses (N, 3) at times t (N,) [s] onto t_query (Q,); θ unwrapped."""
    t = np.asarray(t, float)
    poses = np.asarray(poses, float)
    out = np.empty((len(t_query), 3))
    out[:, 0] = np.interp(t_query, t, poses[:, 0])
    out[:, 1] = np.interp(t_query, t, poses[:, 1])
    out[:, 2] = wrap_angle(np.interp(t_query, t, np.unwrap(poses[:, 2])))
    return out


def robust_sigma(e: np.ndarray) -> float:
    """σ of residuals ``e`` from their median absolute deviation (1.4826 MAD: the σ of a normal
    core, whatever the outliers)."""
    return 1.4826 * float(np.median(np.abs(e - np.median(e))))


def position_errors(est: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Euclidean position error per timestamp (N,) [m]."""
    return np.linalg.norm(np.asarray(est)[:, :2] - np.asarray(gt)[:, :2], axis=1)


def ate_rmse(est: np.ndarray, gt: np.ndarray) -> float:
    """Absolute trajectory error, RMSE of position errors [m] (no alignment)."""
    e = position_errors(est, gt)
    return float(np.sqrt(np.mean(e * e))) if e.size else float("nan")


def heading_rmse(est: np.ndarray, gt: np.ndarray) -> float:
    """RMSE of heading errors [rad]."""
    d = wrap_angle(np.asarray(est)[:, 2] - np.asarray(gt)[:, 2])
    return float(np.sqrt(np.mean(d * d))) if d.size else float("nan")


def rpe_rmse(t: np.ndarray, est: np.ndarray, gt: np.ndarray, delta: float = 1.0) -> float:
    """Relative pose error [m]: RMSE of the translation of (gt_i⁻¹ gt_j)⁻¹ (est_i⁻¹ est_j) over
    pairs with t_j the first time at least ``delta`` [s] after t_i."""
    t = np.asarray(t, float)
    j = np.searchsorted(t, t + delta)
    i = np.flatnonzero(j < t.size)
    if i.size == 0:
        return float("nan")
    j = j[i]
    d_est = between(est[i], est[j])
    d_gt = between(gt[i], gt[j])
    err = between(d_gt, d_est)
    return float(np.sqrt(np.mean(err[:, 0] ** 2 + err[:, 1] ** 2)))


def longest_stay(t: np.ndarray, xy: np.ndarray, radius: float = 0.2) -> tuple[float, int]:
    """Longest time a robot stayed put: the largest t_j − t_i [s] such that every position from i
    to j is within ``radius`` [m] of position i, and that i (times t (N,) [s], positions xy (N, 2+)
    [m]; the first such stretch where several are as long)."""
    t = np.asarray(t, float)
    xy = np.asarray(xy, float)[:, :2]
    best, start = 0.0, 0
    for i in range(len(t)):
        away = np.flatnonzero(np.hypot(*(xy[i + 1:] - xy[i]).T) > radius)
        j = i + int(away[0]) if away.size else len(t) - 1  # the last index still within
        if t[j] - t[i] > best:
            best, start = float(t[j] - t[i]), i
    return best, start
