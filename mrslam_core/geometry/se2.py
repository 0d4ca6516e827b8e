"""SE(2) poses as arrays ``(..., 3)`` = (x [m], y [m], theta [rad]), vectorised over leading axes."""

from __future__ import annotations

import numpy as np


def wrap_angle(a: np.ndarray | float) -> np.ndarray:
    """Wrap angles (rad) to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a ⊕ b: pose b (expressed in frame a) moved into a's parent frame. Shapes broadcast, (..., 3)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    out[..., 1] = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    out[..., 2] = wrap_angle(a[..., 2] + b[..., 2])
    return out


def inverse(a: np.ndarray) -> np.ndarray:
    """⊖a, so that compose(a, inverse(a)) is the identity. (..., 3)."""
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    out = np.empty(a.shape)
    out[..., 0] = -c * a[..., 0] - s * a[..., 1]
    out[..., 1] = s * a[..., 0] - c * a[..., 1]
    out[..., 2] = wrap_angle(-a[..., 2])
    return out


def between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """⊖a ⊕ b: pose b expressed in frame a (the relative motion from a to b). (..., 3)."""
    return compose(inverse(a), b)


def pose_moments(poses: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean (3,) and covariance (3, 3) of poses (M, 3) with weights w (M,) summing to 1:
    θ by its circular mean, deviations wrapped."""
    mean = w @ poses
    mean[2] = np.arctan2(w @ np.sin(poses[:, 2]), w @ np.cos(poses[:, 2]))
    d = poses - mean
    d[:, 2] = wrap_angle(d[:, 2])
    return mean, (w[:, None] * d).T @ d


def transform_points(pose: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Points (..., N, 2 or 3) in the pose's frame -> parent frame; z (if any) unchanged.

    ``pose`` has shape (..., 3) and broadcasts against the points' leading axes.
    """
    pose = np.asarray(pose, dtype=float)
    pts = np.asarray(pts, dtype=float)
    c = np.cos(pose[..., 2])[..., None]
    s = np.sin(pose[..., 2])[..., None]
    out = np.array(pts, dtype=float, copy=True)
    out[..., 0] = pose[..., 0, None] + c * pts[..., 0] - s * pts[..., 1]
    out[..., 1] = pose[..., 1, None] + s * pts[..., 0] + c * pts[..., 1]
    return out


def yaw_to_quaternion(theta: np.ndarray) -> np.ndarray:
    """Yaw (rad) to quaternions (..., 4) in (qx, qy, qz, qw) order (TUM and ROS order)."""
    theta = np.asarray(theta, dtype=float)
    q = np.zeros(theta.shape + (4,))
    q[..., 2] = np.sin(theta / 2.0)
    q[..., 3] = np.cos(theta / 2.0)
    return q


def quaternion_to_yaw(q: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) in (qx, qy, qz, qw) order to yaw (rad) about z."""
    q = np.asarray(q, dtype=float)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def planar_from_matrix(pose: np.ndarray) -> np.ndarray:
    """(..., 3) x [m], y [m], yaw [rad] of (..., 4, 4) homogeneous poses: their projection into the
    plane of the map (yaw = atan2(R10, R00))."""
    pose = np.asarray(pose, float)
    return np.stack([pose[..., 0, 3], pose[..., 1, 3], np.arctan2(pose[..., 1, 0], pose[..., 0, 0])], axis=-1)
