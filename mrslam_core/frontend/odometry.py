"""Stereo visual odometry: the camera's motion between consecutive frames from its tracked points.

Per frame, the points that continue a track have a 3D point in the previous rectified left camera
(P, with its covariance Σp) and a pixel and 3D point in the current one (u, Q, Σq). The motion is

1. hypothesised robustly by OpenCV's PnP in RANSAC (P against u, AP3P minimal samples), then
2. refined by Gauss-Newton on the 3D residuals under both points' stereo covariances,
   ν = P − (R·Q + t), S = Σp + R·Σq·Rᵀ, minimising Σ νᵀS⁻¹ν over the pairs inside the χ²(3)
   gate (re-classified at every iteration), which is the maximum-likelihood motion under the
   frontend's own noise model (000 eq. 12). Its covariance is the inverse of the Gauss-Newton
   information, H⁻¹ = (Σ JᵀS⁻¹J)⁻¹.

Pairs outside the gate at the solution are look-alikes or wrong stereo matches: their tracks end.

Conventions: the motion is the pose of the CURRENT camera in the PREVIOUS camera's frame,
p_prev = R·p_cur + t, rectified left optical frames (x right, y down, z forward) [m]. Its 6 × 6
covariance is over (δθ, δt): R = R̂·exp([δθ]×) (a rotation vector in the current camera frame
[rad]) and t = t̂ + δt (previous camera frame [m]).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from mrslam_core.linalg import quad_form, sym_inv_det

#: fewest pairs PnP RANSAC is tried on (AP3P needs 4: three to solve, one to choose)
MIN_PAIRS = 6


def so3_exp(w: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of a rotation vector w (3,) [rad] (Rodrigues)."""
    return cv2.Rodrigues(np.asarray(w, float).reshape(3, 1))[0]


def skew(v: np.ndarray) -> np.ndarray:
    """[v]× for v (..., 3) -> (..., 3, 3)."""
    v = np.asarray(v, float)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


@dataclass(frozen=True)
class CameraMotion:
    """Motion of the camera between two frames.

    Attributes:
        rotation: (3, 3) R, p_prev = R·p_cur + t.
        translation: (3,) t [m].
        cov: (6, 6) covariance of (δθ [rad], δt [m]) (module docstring).
        inliers: (N,) bool over the candidate pairs: inside the χ² gate at the solution.
    """

    rotation: np.ndarray
    translation: np.ndarray
    cov: np.ndarray
    inliers: np.ndarray

    @classmethod
    def identity(cls, cov: np.ndarray, n: int = 0) -> CameraMotion:
        return cls(np.eye(3), np.zeros(3), np.asarray(cov, float), np.zeros(n, bool))

    def matrix(self) -> np.ndarray:
        """(4, 4) homogeneous T_prev_cur."""
        out = np.eye(4)
        out[:3, :3] = self.rotation
        out[:3, 3] = self.translation
        return out


def _residuals(rot, trans, prev, prev_cov, cur, cur_cov):
    nu = prev - (cur @ rot.T + trans)
    s = prev_cov + rot @ cur_cov @ rot.T
    inv, _ = sym_inv_det(s)
    return nu, inv


def refine_motion(
    rot: np.ndarray, trans: np.ndarray, prev: np.ndarray, prev_cov: np.ndarray, cur: np.ndarray,
    cur_cov: np.ndarray, gate: float, iterations: int = 6,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Gauss-Newton on Σ νᵀS⁻¹ν over the pairs inside the χ²(3) ``gate`` (module docstring).

    Args:
        rot, trans: (3, 3), (3,) initial motion, p_prev = R·p_cur + t.
        prev, prev_cov: (N, 3), (N, 3, 3) points of the previous frame and their covariances.
        cur, cur_cov: (N, 3), (N, 3, 3) the same tracks' points of the current frame.
        gate: χ²(3) quantile a pair's squared Mahalanobis residual must not exceed.
        iterations: Gauss-Newton steps.

    Returns:
        (R (3, 3), t (3,), covariance (6, 6) of (δθ, δt), inliers (N,) bool).
    """
    rot, trans = np.asarray(rot, float), np.asarray(trans, float)
    cov = np.full((6, 6), np.nan)
    inl = np.zeros(prev.shape[0], bool)
    for _ in range(iterations + 1):
        nu, inv = _residuals(rot, trans, prev, prev_cov, cur, cur_cov)
        inl = quad_form(nu, inv) <= gate
        if inl.sum() < 3:
            return rot, trans, np.full((6, 6), np.nan), inl
        jac = np.concatenate([rot @ skew(cur[inl]), -np.broadcast_to(np.eye(3), (int(inl.sum()), 3, 3))], axis=2)
        jt_inv = np.swapaxes(jac, 1, 2) @ inv[inl]  # (n, 6, 3)
        h = (jt_inv @ jac).sum(axis=0)
        g = np.einsum("nij,nj->i", jt_inv, nu[inl])
        try:
            cov = np.linalg.inv(h)
        except np.linalg.LinAlgError:
            return rot, trans, np.full((6, 6), np.nan), inl
        step = -cov @ g
        rot = rot @ so3_exp(step[:3])
        trans = trans + step[3:]
    nu, inv = _residuals(rot, trans, prev, prev_cov, cur, cur_cov)
    return rot, trans, 0.5 * (cov + cov.T), quad_form(nu, inv) <= gate


def estimate_motion(
    prev: np.ndarray, prev_cov: np.ndarray, cur_xy: np.ndarray, cur: np.ndarray, cur_cov: np.ndarray,
    f: float, cx: float, cy: float, *, gate: float, ransac_px: float, ransac_iterations: int,
    min_inliers: int,
) -> CameraMotion | None:
    """The camera's motion from N candidate track pairs, or None when it cannot be estimated.

    Args:
        prev, prev_cov: (N, 3), (N, 3, 3) the pairs' points in the previous rectified left
            camera [m, m²].
        cur_xy: (N, 2) their pixels (column, row) in the current rectified left image [px].
        cur, cur_cov: (N, 3), (N, 3, 3) their points in the current camera [m, m²].
        f, cx, cy: rectified pinhole parameters [px].
        gate: χ²(3) gate of a pair's residual under both covariances.
        ransac_px: PnP RANSAC inlier threshold on the reprojection error [px].
        ransac_iterations: PnP RANSAC iterations.
        min_inliers: fewer pairs inside the gate at the solution: no estimate.

    Returns:
        The motion with its covariance and inlier mask, or None (too few pairs, RANSAC failed,
        too few inliers, or a degenerate configuration).
    """
    n = prev.shape[0]
    if n < max(MIN_PAIRS, min_inliers):
        return None
    k = np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])
    cv2.setRNGSeed(0)  # OpenCV's RANSAC draws from its global generator: the same frames, the same motion
    ok, rvec, tvec, idx = cv2.solvePnPRansac(
        np.ascontiguousarray(prev, np.float64), np.ascontiguousarray(cur_xy, np.float64), k, None,
        iterationsCount=ransac_iterations, reprojectionError=ransac_px, confidence=0.999,
        flags=cv2.SOLVEPNP_AP3P,
    )
    if not ok or idx is None or len(idx) < min_inliers:
        return None
    r_cp = cv2.Rodrigues(rvec)[0]  # p_cur = R_cp·p_prev + t_cp
    rot, trans = r_cp.T, -r_cp.T @ tvec.reshape(3)
    rot, trans, cov, inl = refine_motion(rot, trans, prev, prev_cov, cur, cur_cov, gate)
    if inl.sum() < min_inliers or not np.all(np.isfinite(cov)):
        return None
    return CameraMotion(rot, trans, cov, inl)


def predict_pixels(
    motion: CameraMotion, points: np.ndarray, cov: np.ndarray, f: float, cx: float, cy: float,
    sigma_px: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where points of the previous frame appear in the current image, with their 2 × 2
    covariance, given a predicted camera motion.

    Args:
        motion: predicted motion (pose of the current camera in the previous one) and its
            covariance.
        points, cov: (T, 3), (T, 3, 3) points in the previous rectified left camera [m, m²].
        f, cx, cy: rectified pinhole parameters [px].
        sigma_px: detection noise of a keypoint [px], added on both image axes.

    Returns:
        (uv (T, 2) [px], covariance (T, 2, 2) [px²], in_front (T,) bool: the point lies ahead of
        the current camera).
    """
    r, t = motion.rotation, motion.translation
    q = (points - t) @ r  # Rᵀ(p − t): the point in the current camera
    z = q[:, 2]
    front = z > 1e-3
    zs = np.where(front, z, 1.0)
    uv = np.stack([f * q[:, 0] / zs + cx, f * q[:, 1] / zs + cy], axis=1)
    proj = np.zeros((points.shape[0], 2, 3))
    proj[:, 0, 0] = proj[:, 1, 1] = f / zs
    proj[:, 0, 2] = -f * q[:, 0] / zs**2
    proj[:, 1, 2] = -f * q[:, 1] / zs**2
    # q = exp(−[δθ]×)·R̂ᵀ(p − t̂ − δt) ≈ q̂ + [q̂]×δθ − R̂ᵀδt; the point itself moves with R̂ᵀ
    jm = np.concatenate([skew(q), -np.broadcast_to(r.T, (points.shape[0], 3, 3))], axis=2)
    cq = jm @ motion.cov @ np.swapaxes(jm, 1, 2) + r.T @ cov @ r
    s = proj @ cq @ np.swapaxes(proj, 1, 2) + sigma_px**2 * np.eye(2)
    return uv, s, front


def planar_motion(delta: np.ndarray) -> np.ndarray:
    """(4, 4) T_prev_cur of a planar motion (3,) dx [m], dy [m], dθ [rad] in the previous base
    frame (wheel odometry), for :meth:`Frontend.motion_prior`."""
    dx, dy, dth = (float(v) for v in delta)
    t = np.eye(4)
    t[:3, :3] = so3_exp([0.0, 0.0, dth])
    t[:3, 3] = [dx, dy, 0.0]
    return t
