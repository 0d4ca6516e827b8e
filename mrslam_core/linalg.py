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


def sym3_inv_quad_det(p, q, s, d, e, f, x, y, z) -> tuple[np.ndarray, np.ndarray]:
    """vᵀ A⁻¹ v and det A for the symmetric 3×3 A = [[p, q, s], [q, d, e], [s, e, f]] and v = (x, y, z),
    given as its six distinct terms (arrays of one shape), from the adjugate."""
    c00 = d * f - e * e
    c01 = s * e - q * f
    c02 = q * e - s * d
    det = p * c00 + q * c01 + s * c02
    num = c00 * x * x + (p * f - s * s) * y * y + (p * d - q * q) * z * z
    num += 2.0 * (c01 * x * y + c02 * x * z + (q * s - p * e) * y * z)
    with np.errstate(divide="ignore", invalid="ignore"):
        return num / det, det


def inv_quad_det(a: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """vᵀ A⁻¹ v and det A for symmetric A (..., n, n), v (..., n), without forming A⁻¹ (n ≤ 3)."""
    n = a.shape[-1]
    if n == 3:
        return sym3_inv_quad_det(a[..., 0, 0], a[..., 0, 1], a[..., 0, 2], a[..., 1, 1], a[..., 1, 2], a[..., 2, 2],
                                 v[..., 0], v[..., 1], v[..., 2])
    inv, det = sym_inv_det(a)
    return quad_form(v, inv), det


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


def rotate_z_sym3(a: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Rz(θ) · A · Rz(θ)ᵀ for symmetric A (..., 3, 3) and angles θ (rad); shapes broadcast."""
    c, s = np.cos(theta), np.sin(theta)
    axx, axy, axz = a[..., 0, 0], a[..., 0, 1], a[..., 0, 2]
    ayy, ayz, azz = a[..., 1, 1], a[..., 1, 2], a[..., 2, 2]
    cc, ss, cs = c * c, s * s, c * s
    xx = cc * axx - 2 * cs * axy + ss * ayy
    shape = xx.shape
    out = np.empty(shape + (3, 3))
    out[..., 0, 0] = xx
    out[..., 1, 1] = ss * axx + 2 * cs * axy + cc * ayy
    out[..., 0, 1] = out[..., 1, 0] = cs * (axx - ayy) + (cc - ss) * axy
    out[..., 0, 2] = out[..., 2, 0] = c * axz - s * ayz
    out[..., 1, 2] = out[..., 2, 1] = s * axz + c * ayz
    out[..., 2, 2] = np.broadcast_to(azz, shape)
    return out


def sym3_kalman(sig: np.ndarray, s: np.ndarray, diff: np.ndarray):
    """Kalman step with H = I for stacks of 3×3 symmetric Σ (…, 3, 3), S = Σ + R and innovation
    ν (…, 3): returns (Σ S⁻¹ ν, Σ − Σ S⁻¹ Σ, νᵀ S⁻¹ ν, det S), written out entry by entry
    (about three times faster than batched matmul for small matrices)."""
    a, det = sym_inv_det(s)
    # T = Σ · S⁻¹ (general 3×3)
    t = np.empty_like(sig)
    for i in range(3):
        for j in range(3):
            t[..., i, j] = sig[..., i, 0] * a[..., 0, j] + sig[..., i, 1] * a[..., 1, j] + sig[..., i, 2] * a[..., 2, j]
    shift = np.stack(
        [t[..., i, 0] * diff[..., 0] + t[..., i, 1] * diff[..., 1] + t[..., i, 2] * diff[..., 2] for i in range(3)], -1
    )
    new = np.empty_like(sig)
    for i in range(3):
        for j in range(i, 3):
            v = sig[..., i, j] - (t[..., i, 0] * sig[..., 0, j] + t[..., i, 1] * sig[..., 1, j] + t[..., i, 2] * sig[..., 2, j])
            new[..., i, j] = v
            new[..., j, i] = v
    return shift, new, quad_form(diff, a), det
