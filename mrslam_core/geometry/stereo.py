"""Rectified stereo triangulation and its covariance (000, eq. 12).

Conventions: pixel (r, c) = (row, column) in the rectified LEFT image, disparity d = c_left − c_right
> 0 [px], focal length f [px], principal point (cx, cy) [px], baseline b [m]. The point is returned
in the left camera's OPTICAL frame (REP-103: x right, y down, z forward), which is what ROS and
OpenCV use. Eq. 12 of the paper is written with Y up, ``Y = b(cy − r)/d``; the optical-frame y is its
negative, ``y = b(r − cy)/d``, and the covariance is the same up to that sign flip.
"""

from __future__ import annotations

import numpy as np


def triangulate(
    r: np.ndarray, c: np.ndarray, d: np.ndarray, f: float, cx: float, cy: float, baseline: float
) -> np.ndarray:
    """Points (N, 3) in the left optical frame [m] from row, column, disparity (N,) [px]."""
    r, c, d = (np.asarray(v, dtype=float) for v in (r, c, d))
    z = f * baseline / d
    return np.stack([baseline * (c - cx) / d, baseline * (r - cy) / d, z], axis=-1)


def triangulation_jacobian(
    r: np.ndarray, c: np.ndarray, d: np.ndarray, f: float, cx: float, cy: float, baseline: float
) -> np.ndarray:
    """J = ∂(x, y, z)/∂(d, r, c), shape (N, 3, 3), columns ordered (d, r, c) as in the paper."""
    r, c, d = (np.asarray(v, dtype=float) for v in (r, c, d))
    n = np.broadcast(r, c, d).shape
    jac = np.zeros(n + (3, 3))
    jac[..., 0, 0] = -baseline * (c - cx) / d**2
    jac[..., 0, 2] = baseline / d
    jac[..., 1, 0] = -baseline * (r - cy) / d**2
    jac[..., 1, 1] = baseline / d
    jac[..., 2, 0] = -f * baseline / d**2
    return jac


def triangulation_covariance(
    r: np.ndarray,
    c: np.ndarray,
    d: np.ndarray,
    f: float,
    cx: float,
    cy: float,
    baseline: float,
    sigma_d: float,
    sigma_r: float,
    sigma_c: float,
) -> np.ndarray:
    """R = J · diag(σd², σr², σc²) · Jᵀ, shape (N, 3, 3) [m²], in the left optical frame."""
    jac = triangulation_jacobian(r, c, d, f, cx, cy, baseline)
    rsp = np.array([sigma_d**2, sigma_r**2, sigma_c**2])
    return np.einsum("...ij,j,...kj->...ik", jac, rsp, jac)


def project(points: np.ndarray, f: float, cx: float, cy: float, baseline: float) -> np.ndarray:
    """Inverse of :func:`triangulate`: points (N, 3) optical frame -> (r, c, d) (N, 3) [px]."""
    p = np.asarray(points, dtype=float)
    d = f * baseline / p[..., 2]
    c = cx + f * p[..., 0] / p[..., 2]
    r = cy + f * p[..., 1] / p[..., 2]
    return np.stack([r, c, d], axis=-1)


def optical_to_body(points: np.ndarray, cov: np.ndarray | None, t_body_cam: np.ndarray):
    """Move points (N, 3) and covariances (N, 3, 3) from a camera frame into the body frame.

    Args:
        points: (N, 3) in the camera frame [m].
        cov: (N, 3, 3) [m²] or None.
        t_body_cam: (4, 4) homogeneous transform body <- camera.

    Returns:
        (points_body (N, 3), cov_body (N, 3, 3) or None).
    """
    rot = np.asarray(t_body_cam, dtype=float)[:3, :3]
    trans = np.asarray(t_body_cam, dtype=float)[:3, 3]
    pts = np.asarray(points, dtype=float) @ rot.T + trans
    if cov is None:
        return pts, None
    return pts, rot @ np.asarray(cov, dtype=float) @ rot.T
