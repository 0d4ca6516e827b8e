"""Closed-form batched linear algebra for the small symmetric matrices of the filter.

numpy's batched ``inv``/``det`` call LAPACK once per matrix, which dominates a filter step with
10⁵ 3×3 innovation covariances; these closed forms are plain array arithmetic instead.
All functions take stacks ``(..., n, n)`` with n = 2 or 3 and treat the input as symmetric.
"""

from __future__ import annotations

import numpy as np


def sym_inv_det(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse and determinant of symmetric matrices (..., n, n), n in {2, 3}.

    Returns:
        (inverse (..., n, n), determinant (...)). Singular inputs give inf/nan, which callers
        treat as a failed gate.
    """
    n = a.shape[-1]
    if n == 2:
        p, q, r = a[..., 0, 0], a[..., 0, 1], a[..., 1, 1]
        det = p * r - q * q
        inv = np.empty_like(a)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv[..., 0, 0] = r / det
            inv[..., 1, 1] = p / det
            inv[..., 0, 1] = inv[..., 1, 0] = -q / det
        return inv, det
    if n == 3:
        p, q, s = a[..., 0, 0], a[..., 0, 1], a[..., 0, 2]
        d, e, f = a[..., 1, 1], a[..., 1, 2], a[..., 2, 2]
        c00 = d * f - e * e
        c01 = s * e - q * f
        c02 = q * e - s * d
        c11 = p * f - s * s
        c12 = q * s - p * e
        c22 = p * d - q * q
        det = p * c00 + q * c01 + s * c02
        inv = np.empty_like(a)
        with np.errstate(divide="ignore", invalid="ignore"):
            r = 1.0 / det
            inv[..., 0, 0] = c00 * r
            inv[..., 1, 1] = c11 * r
            inv[..., 2, 2] = c22 * r
            inv[..., 0, 1] = inv[..., 1, 0] = c01 * r
            inv[..., 0, 2] = inv[..., 2, 0] = c02 * r
            inv[..., 1, 2] = inv[..., 2, 1] = c12 * r
        return inv, det
    return np.linalg.inv(a), np.linalg.det(a)


def quad_form(v: np.ndarray, a: np.ndarray) -> np.ndarray:
    """vᵀ A v for stacks v (..., n) and symmetric A (..., n, n) -> (...)."""
    n = v.shape[-1]
    if n == 3:
        x, y, z = v[..., 0], v[..., 1], v[..., 2]
        return (
            a[..., 0, 0] * x * x + a[..., 1, 1] * y * y + a[..., 2, 2] * z * z
            + 2.0 * (a[..., 0, 1] * x * y + a[..., 0, 2] * x * z + a[..., 1, 2] * y * z)
        )
    if n == 2:
        x, y = v[..., 0], v[..., 1]
        return a[..., 0, 0] * x * x + a[..., 1, 1] * y * y + 2.0 * a[..., 0, 1] * x * y
    return np.einsum("...i,...ij,...j->...", v, a, v)


def is_positive_definite(a: np.ndarray) -> np.ndarray:
    """Per-matrix test (Sylvester's criterion) for symmetric (..., n, n), n in {2, 3}; (...) bool."""
    n = a.shape[-1]
    ok = np.isfinite(a).all(axis=(-1, -2)) & (a[..., 0, 0] > 0)
    with np.errstate(invalid="ignore"):
        if n >= 2:
            ok &= a[..., 0, 0] * a[..., 1, 1] - a[..., 0, 1] * a[..., 1, 0] > 0
        if n == 3:
            ok &= sym_inv_det(a)[1] > 0
        if n > 3:
            ok &= np.all(np.linalg.eigvalsh(a) > 0, axis=-1)
    return ok
