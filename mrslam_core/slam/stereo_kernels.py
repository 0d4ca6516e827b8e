"""Compiled kernels of the stereo point model (:class:`~mrslam_core.slam.models.StereoPointModel`):
the χ² gate over candidate pairs, the EKF update of chosen pairs, and the per-pair terms of the
FastSLAM 2.0 proposal.

All work in the map frame with H = I (see the model's docstring): S = Σ + Rz R Rzᵀ (+ J P Jᵀ for
a pose uncertain by P, J = ∂(g⁻¹(x, z) − μ)/∂x restricted to its non-zero rows), innovation
ν = g⁻¹(x, z) − μ. Every 3×3 symmetric matrix is carried as its six distinct terms, in the order
(xx, xy, xz, yy, yz, zz). The arithmetic follows the numpy code these kernels replaced term by
term (same operations in the same order, no fused multiply-add), so FastSLAM 1.0 results are
bit for bit those of the numpy version. Transcendentals (cos, sin, log) stay in numpy, outside.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _sym3_inverse(p, q, sx, d, e, f):
    """The inverse's six terms (a00, a01, a02, a11, a12, a22) and the determinant of the symmetric
    3×3 [[p, q, sx], [q, d, e], [sx, e, f]], from the adjugate."""
    c00 = d * f - e * e
    c01 = sx * e - q * f
    c02 = q * e - sx * d
    c11 = p * f - sx * sx
    c12 = q * sx - p * e
    c22 = p * d - q * q
    dt = p * c00 + q * c01 + sx * c02
    inv = 1.0 / dt
    return c00 * inv, c01 * inv, c02 * inv, c11 * inv, c12 * inv, c22 * inv, dt


@njit(cache=True, inline="always")
def _rotated(ci, si, rxx, rxy, rxz, ryy, ryz):
    """The terms (xx, yy, xy, xz, yz) of Rz R Rzᵀ that the rotation changes (zz is R's)."""
    cc, ss, cs = ci * ci, si * si, ci * si
    return (cc * rxx - 2 * cs * rxy + ss * ryy, ss * rxx + 2 * cs * rxy + cc * ryy,
            cs * (rxx - ryy) + (cc - ss) * rxy, ci * rxz - si * ryz, si * rxz + ci * ryz)


#: pairs whose pool rows are loaded ahead of their arithmetic (:func:`_touch`)
_AHEAD = 32


@njit(cache=True, inline="always")
def _touch(mean, cov, rows):
    """Load ``rows`` of the pools mean (R, 3) and cov (R, 9) (first and last value: every cache
    line a row spans). The loads are independent, so their cache misses overlap, and the
    arithmetic that follows finds the rows in cache: the rows lie scattered over tens of MB of
    pool, and the kernels wait on memory, not on arithmetic. Returns the values' sum, which the
    kernels return (and callers drop) so the loads are kept."""
    acc = 0.0
    for i in range(rows.size):
        acc += mean[rows[i], 0] + mean[rows[i], 2] + cov[rows[i], 0] + cov[rows[i], 8]
    return acc


@njit(cache=True)
def observation_terms(pose, c, s, z, r, lm, rn):
    """What the gate needs per particle and observation: the observation in the map frame
    g⁻¹(x, z) and the distinct terms of Rz(θ) R Rz(θ)ᵀ.

    Args:
        pose: (M, 3) poses; c, s: (M,) cos θ and sin θ.
        z: (1, B, 3) observations and r: (1, B, 3, 3) their covariances (base_link) [m, m²], or
            (M, B, ...): each particle's own.
        lm: (M, B, 3) and rn: (M, B, 6) outputs, map frame.
    """
    for p in range(c.size):
        pr = p if r.shape[0] > 1 else 0
        pz = p if z.shape[0] > 1 else 0
        for b in range(r.shape[1]):
            zx, zy = z[pz, b, 0], z[pz, b, 1]
            lm[p, b, 0] = pose[p, 0] + c[p] * zx - s[p] * zy
            lm[p, b, 1] = pose[p, 1] + s[p] * zx + c[p] * zy
            lm[p, b, 2] = z[pz, b, 2]
            rxx, rxy, rxz = r[pr, b, 0, 0], r[pr, b, 0, 1], r[pr, b, 0, 2]
            ryy, ryz = r[pr, b, 1, 1], r[pr, b, 1, 2]
            xx, yy, xy, xz, yz = _rotated(c[p], s[p], rxx, rxy, rxz, ryy, ryz)
            rn[p, b, 0], rn[p, b, 1], rn[p, b, 2] = xx, xy, xz
            rn[p, b, 3], rn[p, b, 4], rn[p, b, 5] = yy, yz, r[pr, b, 2, 2]


@njit(cache=True)
def new_points(pose, c, s, z, r, bi, lm, cov):
    """New landmarks of P pairs, each its own pose: g⁻¹(x, z) and Rz(θ) R Rz(θ)ᵀ, as
    :func:`observation_terms` computes them.

    Args:
        pose: (P, 3) each pair's pose; c, s: (P,) cos θ and sin θ.
        z: (B, 3) observations and r: (B, 3, 3) their covariances (base_link) [m, m²]; bi: (P,)
            the observation of each pair.
        lm: (P, 3) and cov: (P, 9) outputs, map frame.
    """
    for i in range(bi.size):
        b = bi[i]
        zx, zy = z[b, 0], z[b, 1]
        lm[i, 0] = pose[i, 0] + c[i] * zx - s[i] * zy
        lm[i, 1] = pose[i, 1] + s[i] * zx + c[i] * zy
        lm[i, 2] = z[b, 2]
        xx, yy, xy, xz, yz = _rotated(c[i], s[i], r[b, 0, 0], r[b, 0, 1], r[b, 0, 2], r[b, 1, 1], r[b, 1, 2])
        cov[i, 0], cov[i, 1], cov[i, 2] = xx, xy, xz
        cov[i, 3], cov[i, 4], cov[i, 5] = xy, yy, yz
        cov[i, 6], cov[i, 7], cov[i, 8] = xz, yz, r[b, 2, 2]


@njit(cache=True)
def gate(lm, rn, pose, pose_cov, mean, cov, rows, vb, maha, det):
    """Mahalanobis distance νᵀS⁻¹ν and det S of every particle's candidate pairs, read straight
    from the landmark pools (no gathered copies).

    Args:
        lm: (M, B, 3) each observation in the map frame, per particle [m].
        rn: (M, B, 6) Rz R Rzᵀ terms (:func:`observation_terms`).
        pose: (M, 3) poses; read only with ``pose_cov``.
        pose_cov: (M, 6) terms of each pose's covariance P (FastSLAM 2.0 prediction), or (0, 6):
            none (FastSLAM 1.0).
        mean: (R, 3) float32 pool rows of landmark means; cov: (R, 9) float32 covariances.
        rows: (M, V) pool row of each particle's pair v; vb: (V,) observation of pair v.
        maha, det: (M, V) outputs.

    Returns:
        a number to drop (:func:`_touch`).
    """
    with_pose = pose_cov.shape[0] > 0
    sink = 0.0
    for m in range(rows.shape[0]):
        sink += _touch(mean, cov, rows[m])
        for v in range(rows.shape[1]):
            row = rows[m, v]
            b = vb[v]
            mx, my, mz = np.float64(mean[row, 0]), np.float64(mean[row, 1]), np.float64(mean[row, 2])
            p = cov[row, 0] + rn[m, b, 0]
            q = cov[row, 1] + rn[m, b, 1]
            sx = cov[row, 2] + rn[m, b, 2]
            d = cov[row, 4] + rn[m, b, 3]
            e = cov[row, 5] + rn[m, b, 4]
            f = cov[row, 8] + rn[m, b, 5]
            if with_pose:
                dx = mx - pose[m, 0]
                dy = my - pose[m, 1]
                pc = pose_cov[m]
                p += pc[0] - 2.0 * dy * pc[2] + dy * dy * pc[5]
                q += pc[1] + dx * pc[2] - dy * pc[4] - dx * dy * pc[5]
                d += pc[3] + 2.0 * dx * pc[4] + dx * dx * pc[5]
            x = lm[m, b, 0] - mx
            y = lm[m, b, 1] - my
            zz = lm[m, b, 2] - mz
            c00 = d * f - e * e
            c01 = sx * e - q * f
            c02 = q * e - sx * d
            dt = p * c00 + q * c01 + sx * c02
            num = c00 * x * x + (p * f - sx * sx) * y * y + (p * d - q * q) * zz * zz
            num += 2.0 * (c01 * x * y + c02 * x * zz + (q * sx - p * e) * y * zz)
            maha[m, v] = num / dt
            det[m, v] = dt
    return sink


@njit(cache=True)
def kalman(pose, c, s, z, r, pi, bi, mean, cov, rows, new_mu, new_sig, maha, det):
    """EKF update of P chosen pairs (particle pi[i], observation bi[i], landmark at rows[i]):
    S = Σ + Rz R Rzᵀ, A = S⁻¹ (cofactors), T = Σ A, μ' = μ + T ν, Σ' = Σ − T Σ.

    Args:
        pose: (M, 3); c, s: (M,) cos/sin of the pose angles; z: (B, 3); r: (B, 3, 3).
        pi, bi: (P,) particle and observation of each pair.
        mean: (R, 3), cov: (R, 9) landmark values by row (float32 pools or float64), read at
            rows (P,).
        new_mu (P, 3), new_sig (P, 9), maha (P,), det (P,): outputs (float64).

    Returns:
        a number to drop (:func:`_touch`).
    """
    sink = 0.0
    for i in range(rows.size):
        if i % _AHEAD == 0:  # this block's rows and the next's, each once
            sink += _touch(mean, cov, rows[i + _AHEAD if i else 0 : i + 2 * _AHEAD])
        row = rows[i]
        p, b = pi[i], bi[i]
        ci, si = c[p], s[p]
        s00, s01, s02 = np.float64(cov[row, 0]), np.float64(cov[row, 1]), np.float64(cov[row, 2])
        s11, s12, s22 = np.float64(cov[row, 4]), np.float64(cov[row, 5]), np.float64(cov[row, 8])
        rxx, rxy, rxz = r[b, 0, 0], r[b, 0, 1], r[b, 0, 2]
        ryy, ryz, rzz = r[b, 1, 1], r[b, 1, 2], r[b, 2, 2]
        zx, zy = z[b, 0], z[b, 1]
        mx, my, mz = np.float64(mean[row, 0]), np.float64(mean[row, 1]), np.float64(mean[row, 2])
        x = pose[p, 0] + ci * zx - si * zy - mx
        y = pose[p, 1] + si * zx + ci * zy - my
        zz = z[b, 2] - mz
        rot_xx, rot_yy, rot_xy, rot_xz, rot_yz = _rotated(ci, si, rxx, rxy, rxz, ryy, ryz)
        a00, a01, a02, a11, a12, a22, dt = _sym3_inverse(s00 + rot_xx, s01 + rot_xy, s02 + rot_xz, s11 + rot_yy,
                                                         s12 + rot_yz, s22 + rzz)
        t00 = s00 * a00 + s01 * a01 + s02 * a02
        t01 = s00 * a01 + s01 * a11 + s02 * a12
        t02 = s00 * a02 + s01 * a12 + s02 * a22
        t10 = s01 * a00 + s11 * a01 + s12 * a02
        t11 = s01 * a01 + s11 * a11 + s12 * a12
        t12 = s01 * a02 + s11 * a12 + s12 * a22
        t20 = s02 * a00 + s12 * a01 + s22 * a02
        t21 = s02 * a01 + s12 * a11 + s22 * a12
        t22 = s02 * a02 + s12 * a12 + s22 * a22
        new_mu[i, 0] = mx + t00 * x + t01 * y + t02 * zz
        new_mu[i, 1] = my + t10 * x + t11 * y + t12 * zz
        new_mu[i, 2] = mz + t20 * x + t21 * y + t22 * zz
        v00 = s00 - (t00 * s00 + t01 * s01 + t02 * s02)
        v11 = s11 - (t10 * s01 + t11 * s11 + t12 * s12)
        v22 = s22 - (t20 * s02 + t21 * s12 + t22 * s22)
        v01 = s01 - (t00 * s01 + t01 * s11 + t02 * s12)
        v02 = s02 - (t00 * s02 + t01 * s12 + t02 * s22)
        v12 = s12 - (t10 * s02 + t11 * s12 + t12 * s22)
        new_sig[i, 0], new_sig[i, 1], new_sig[i, 2] = v00, v01, v02
        new_sig[i, 3], new_sig[i, 4], new_sig[i, 5] = v01, v11, v12
        new_sig[i, 6], new_sig[i, 7], new_sig[i, 8] = v02, v12, v22
        maha[i] = a00 * x * x + a11 * y * y + a22 * zz * zz + 2.0 * (a01 * x * y + a02 * x * zz + a12 * y * zz)
        det[i] = dt
    return sink


@njit(cache=True)
def proposal_terms(x, dx, c, s, z, r, pi, bi, mean, cov, rows, info, eta, quad, det, nu, zinv, hx):
    """Per-pair terms of the FastSLAM 2.0 proposal linearised at the poses x (M, 3), map frame:
    Hₓ = ∂(g⁻¹(x, z) − μ)/∂x up to sign = [[−1, 0, Δy], [0, −1, −Δx], [0, 0, 0]] with (Δx, Δy) =
    μ − x, Z = Σ + Rz R Rzᵀ, ν = g⁻¹(x, z) − μ + Hₓ dx (the iterated EKF's shift, dx = x − x̂).

    Args:
        x, dx: (M, 3); c, s: (M,) cos/sin of x's angles; z: (B, 3); r: (B, 3, 3).
        pi, bi, rows: (P,) particle, observation and landmark pool row of each pair; mean (R, 3)
            and cov (R, 9) the pools.
        info (P, 3, 3) HₓᵀZ⁻¹Hₓ, eta (P, 3) HₓᵀZ⁻¹ν, quad (P,) νᵀZ⁻¹ν, det (P,) |Z|, nu (P, 3),
        zinv (P, 3, 3), hx (P, 3, 3): outputs; nu, zinv and hx may be (0, ...): not wanted.

    Returns:
        a number to drop (:func:`_touch`).
    """
    residuals = nu.shape[0] > 0
    sink = 0.0
    for i in range(rows.size):
        if i % _AHEAD == 0:  # this block's rows and the next's, each once
            sink += _touch(mean, cov, rows[i + _AHEAD if i else 0 : i + 2 * _AHEAD])
        p, b, row = pi[i], bi[i], rows[i]
        ci, si = c[p], s[p]
        mx, my, mz = np.float64(mean[row, 0]), np.float64(mean[row, 1]), np.float64(mean[row, 2])
        rxx, rxy, rxz = r[b, 0, 0], r[b, 0, 1], r[b, 0, 2]
        ryy, ryz = r[b, 1, 1], r[b, 1, 2]
        rot_xx, rot_yy, rot_xy, rot_xz, rot_yz = _rotated(ci, si, rxx, rxy, rxz, ryy, ryz)
        a00, a01, a02, a11, a12, a22, dt = _sym3_inverse(
            cov[row, 0] + rot_xx, cov[row, 1] + rot_xy, cov[row, 2] + rot_xz, cov[row, 4] + rot_yy,
            cov[row, 5] + rot_yz, cov[row, 8] + r[b, 2, 2])
        ddx = mx - x[p, 0]
        ddy = my - x[p, 1]
        # ν = g⁻¹(x, z) − μ + Hₓ dx
        n0 = x[p, 0] + ci * z[b, 0] - si * z[b, 1] - mx + (-dx[p, 0] + ddy * dx[p, 2])
        n1 = x[p, 1] + si * z[b, 0] + ci * z[b, 1] - my + (-dx[p, 1] - ddx * dx[p, 2])
        n2 = z[b, 2] - mz
        # A ν and A Hₓ's columns (Hₓ e0 = (−1, 0, 0), Hₓ e1 = (0, −1, 0), Hₓ e2 = (Δy, −Δx, 0))
        an0 = a00 * n0 + a01 * n1 + a02 * n2
        an1 = a01 * n0 + a11 * n1 + a12 * n2
        an2 = a02 * n0 + a12 * n1 + a22 * n2
        h2x, h2y = ddy, -ddx
        ah2_0 = a00 * h2x + a01 * h2y
        ah2_1 = a01 * h2x + a11 * h2y
        info[i, 0, 0] = a00
        info[i, 0, 1] = a01
        info[i, 1, 0] = a01
        info[i, 1, 1] = a11
        info[i, 0, 2] = -ah2_0
        info[i, 2, 0] = -ah2_0
        info[i, 1, 2] = -ah2_1
        info[i, 2, 1] = -ah2_1
        info[i, 2, 2] = h2x * ah2_0 + h2y * ah2_1
        eta[i, 0] = -an0
        eta[i, 1] = -an1
        eta[i, 2] = h2x * an0 + h2y * an1
        quad[i] = n0 * an0 + n1 * an1 + n2 * an2
        det[i] = dt
        if not residuals:
            continue
        nu[i, 0], nu[i, 1], nu[i, 2] = n0, n1, n2
        zinv[i, 0, 0], zinv[i, 0, 1], zinv[i, 0, 2] = a00, a01, a02
        zinv[i, 1, 0], zinv[i, 1, 1], zinv[i, 1, 2] = a01, a11, a12
        zinv[i, 2, 0], zinv[i, 2, 1], zinv[i, 2, 2] = a02, a12, a22
        hx[i, 0, 0], hx[i, 0, 1], hx[i, 0, 2] = -1.0, 0.0, h2x
        hx[i, 1, 0], hx[i, 1, 1], hx[i, 1, 2] = 0.0, -1.0, h2y
        hx[i, 2, 0], hx[i, 2, 1], hx[i, 2, 2] = 0.0, 0.0, 0.0
    return sink
