"""Rigid motions in 3D fitted to matched points (Kabsch / Umeyama without scale)."""

from __future__ import annotations

import numpy as np


def fit_rigid_3d(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rotation and translation with dst ≈ R·src + t, batched.

    The SVD of the cross-covariance of the centred points, Σ s'd'ᵀ = U S Vᵀ, gives
    R = V diag(1, 1, det(VUᵀ)) Uᵀ (a proper rotation, never a reflection) and t = d̄ − R s̄.

    Args:
        src, dst: (..., N, 3) matched points, N >= 3.

    Returns:
        (R (..., 3, 3), t (..., 3)).
    """
    src = np.asarray(src, float)
    dst = np.asarray(dst, float)
    if src.shape != dst.shape or src.shape[-1] != 3 or src.shape[-2] < 3:
        raise ValueError(f"need matching (..., N >= 3, 3) point sets, got {src.shape} and {dst.shape}")
    s_bar = src.mean(-2)
    d_bar = dst.mean(-2)
    h = np.swapaxes(src - s_bar[..., None, :], -1, -2) @ (dst - d_bar[..., None, :])
    u, _, vt = np.linalg.svd(h)
    v = np.swapaxes(vt, -1, -2)
    fix = np.ones(h.shape[:-1])
    fix[..., 2] = np.sign(np.linalg.det(v @ np.swapaxes(u, -1, -2)))
    rot = (v * fix[..., None, :]) @ np.swapaxes(u, -1, -2)
    return rot, d_bar - (rot @ s_bar[..., None])[..., 0]
