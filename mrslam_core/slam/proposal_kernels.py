"""Compiled kernels of the FastSLAM 2.0 proposal (:meth:`MultiRobotFastSLAM._combine
<mrslam_core.slam.filter.MultiRobotFastSLAM>`): sums of per-pair terms by particle, and each
pair's deleted residual for the outlier gate (``_robust_fold``).

The sums: ``np.bincount`` with weights, once per column, did this before; the loop adds in the same order
(pair by pair), so the sums are bit for bit the same.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def sum_terms(index, info, eta, quad, norm, n):
    """Per-particle sums of the proposal's per-pair terms in one pass: ``info`` (P, 9), ``eta``
    (P, 3), ``quad`` (P,) and ``norm`` (P,) grouped by ``index`` (P,) into (n, 9), (n, 3), (n,)
    and (n,)."""
    s_info = np.zeros((n, 9))
    s_eta = np.zeros((n, 3))
    s_quad = np.zeros(n)
    s_norm = np.zeros(n)
    for i in range(index.size):
        m = index[i]
        for c in range(9):
            s_info[m, c] += info[i, c]
        for c in range(3):
            s_eta[m, c] += eta[i, c]
        s_quad[m] += quad[i]
        s_norm[m] += norm[i]
    return s_info, s_eta, s_quad, s_norm


@njit(cache=True, inline="always")
def _cholesky(a, n, out):
    """Lower Cholesky factor of the symmetric (n, n) ``a`` into ``out``; False if not positive definite."""
    for i in range(n):
        for j in range(i + 1):
            s = a[i, j]
            for k in range(j):
                s -= out[i, k] * out[j, k]
            if i == j:
                if not s > 0.0:
                    return False
                out[i, i] = np.sqrt(s)
            else:
                out[i, j] = s / out[j, j]
    return True


@njit(cache=True, inline="always")
def _solve(chol, n, b, out):
    """x with (L Lᵀ) x = b for the Cholesky factor L (n, n), into ``out`` (n,)."""
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= chol[i, k] * out[k]
        out[i] = s / chol[i, i]
    for i in range(n - 1, -1, -1):
        s = out[i]
        for k in range(i + 1, n):
            s -= chol[k, i] * out[k]
        out[i] = s / chol[i, i]


@njit(cache=True, inline="always")
def _sym_inverse(a, j, n, out):
    """Inverse of the symmetric a[j] (n, n), n in {2, 3}, into ``out``, in closed form; False if
    singular."""
    if n == 2:
        p, q, r = a[j, 0, 0], a[j, 0, 1], a[j, 1, 1]
        det = p * r - q * q
        if det == 0.0:
            return False
        out[0, 0], out[1, 1] = r / det, p / det
        out[0, 1] = out[1, 0] = -q / det
        return True
    p, q, w = a[j, 0, 0], a[j, 0, 1], a[j, 0, 2]
    d, e, f = a[j, 1, 1], a[j, 1, 2], a[j, 2, 2]
    c00, c01, c02 = d * f - e * e, w * e - q * f, q * e - w * d
    det = p * c00 + q * c01 + w * c02
    if det == 0.0:
        return False
    r = 1.0 / det
    out[0, 0], out[1, 1], out[2, 2] = c00 * r, (p * f - w * w) * r, (p * d - q * q) * r
    out[0, 1] = out[1, 0] = c01 * r
    out[0, 2] = out[2, 0] = c02 * r
    out[1, 2] = out[2, 1] = (q * w - p * e) * r
    return True


@njit(cache=True)
def deleted_residuals(index, own, shift, cov, nu, zinv, hx):
    """Each pair's innovation against the proposal fitted without it, as a χ²(d) statistic (P,).

    With the fit's shift δₘ = Λₘ⁻¹ηₘ and covariance Cₘ = Λₘ⁻¹ of particle m = ``index[j]``, the
    residual at the fit eⱼ = νⱼ − Hⱼδₘ gives the statistic without refitting: eⱼᵀ(Zⱼ − HⱼCₘHⱼᵀ)⁻¹eⱼ
    for a pair in the fit (``own[j]``; the leave-one-out identity of a linear Gaussian fit, equal
    to its innovation against the fit without it), eⱼᵀ(Zⱼ + HⱼCₘHⱼᵀ)⁻¹eⱼ for a pair left out.
    ``shift`` (M, 3), ``cov`` (M, 3, 3); ``nu`` (P, d), ``zinv`` (P, d, d) the pairs' Zⱼ⁻¹,
    ``hx`` (P, d, 3). A matrix that is not positive definite gives inf (the pair fails any gate).
    """
    p = index.size
    d = nu.shape[1]
    out = np.empty(p)
    hc = np.empty((d, 3))
    s = np.empty((d, d))
    ls = np.empty((d, d))
    z = np.empty((d, d))
    e = np.empty(d)
    x = np.empty(d)
    for j in range(p):
        m = index[j]
        sign = -1.0 if own[j] else 1.0
        if not _sym_inverse(zinv, j, d, z):
            out[j] = np.inf
            continue
        for u in range(d):
            acc = nu[j, u]
            for v in range(3):
                acc -= hx[j, u, v] * shift[m, v]
                t = 0.0
                for w in range(3):
                    t += hx[j, u, w] * cov[m, w, v]
                hc[u, v] = t
            e[u] = acc
        for u in range(d):
            for c in range(u + 1):
                t = 0.0
                for v in range(3):
                    t += hc[u, v] * hx[j, c, v]
                s[u, c] = z[u, c] + sign * t
        if not _cholesky(s, d, ls):
            out[j] = np.inf
            continue
        _solve(ls, d, e, x)
        q = 0.0
        for u in range(d):
            q += e[u] * x[u]
        out[j] = q
    return out
