"""Observation models: how a landmark in the map appears to a robot at an SE(2) pose.

The filter only calls :meth:`score` (Mahalanobis distances and normalisers for many
particle/observation/candidate triples) and :meth:`update` (the EKF step, eqs. 6–11, for the chosen
pairs) and :meth:`inverse` (new landmarks), so any model with this interface plugs in. Poses are
(x [m], y [m], θ [rad]) of base_link in the map frame; all methods broadcast over leading axes.
"""

from __future__ import annotations

import numpy as np

from mrslam_core.geometry.se2 import wrap_angle
from mrslam_core.linalg import quad_form, sym_inv_det
from mrslam_core.slam import stereo_kernels

LOG_2PI = float(np.log(2.0 * np.pi))


def _t(a: np.ndarray) -> np.ndarray:
    return np.swapaxes(a, -1, -2)


class ObservationModel:
    """g(x, l), its Jacobian and inverse, and the generic EKF built on them.

    Subclasses define ``dim``, ``name``, :meth:`predict`, :meth:`innovation` and :meth:`inverse`.
    """

    dim: int
    name: str

    def predict(self, pose: np.ndarray, landmark: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """ẑ = g(x, l) (..., dim) and G = ∂g/∂l (..., dim, dim)."""
        raise NotImplementedError

    def innovation(self, z: np.ndarray, zhat: np.ndarray) -> np.ndarray:
        """z − ẑ with angular components wrapped, (..., dim)."""
        return z - zhat

    def pose_jacobian(self, pose: np.ndarray, landmark: np.ndarray) -> np.ndarray:
        """Hₓ = ∂g/∂x (..., dim, 3) with respect to the robot pose (x, y, θ)."""
        raise NotImplementedError

    def inverse(self, pose: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """l = g⁻¹(x, z) (..., dim) and ∂l/∂z = G⁻¹ (..., dim, dim)."""
        raise NotImplementedError

    def new_landmark(self, pose: np.ndarray, z: np.ndarray, r: np.ndarray):
        """Mean g⁻¹(x, z) and covariance G⁻¹ R G⁻ᵀ (000 Alg. 1 line 36, corrected)."""
        lm, ginv = self.inverse(pose, z)
        return lm, ginv @ r @ _t(ginv)

    def new_landmark_rows(self, pose, z, r, pi, bi):
        """:meth:`new_landmark` of P pairs: particle ``pi`` (P,) of ``pose`` (M, 3), observation
        ``bi`` (P,) of ``z`` (B, dim) and ``r`` (B, dim, dim). Returns (mean (P, dim), covariance
        (P, dim, dim)), map frame."""
        return self.new_landmark(pose[pi], z[bi], r[bi])

    def score(self, pose, z, r, mu, sig, pose_cov=None, index=None) -> tuple[np.ndarray, np.ndarray]:
        """Mahalanobis distance D (eq. 15) and log det(2πZ) for landmark/observation pairs.

        Args (leading axes broadcast, e.g. particles × pairs):
            pose: (..., 3); z: (..., dim); r: (..., dim, dim); mu: (..., dim);
            sig: (..., dim, dim); pose_cov: (..., 3, 3) uncertainty of the pose itself (the
            FastSLAM 2.0 prediction), added as Hₓ P Hₓᵀ, or None; index: (V,) when z and r
            are per observation (…, B, …) and the pairs pick observation ``index[v]``.

        Returns:
            (D (...), log det(2π Z) (...)).
        """
        if index is not None:
            z, r = z[..., index, :], r[..., index, :, :]
        zhat, g = self.predict(pose, mu)
        zmat = g @ sig @ _t(g) + r
        if pose_cov is not None:
            hx = self.pose_jacobian(pose, mu)
            zmat = zmat + hx @ pose_cov @ _t(hx)
        zinv, zdet = sym_inv_det(zmat)
        nu = self.innovation(z, zhat)
        return quad_form(nu, zinv), self.dim * LOG_2PI + np.log(zdet)

    def score_rows(self, pose, z, r, mean, cov, rows, index, pose_cov=None, with_norm=True):
        """:meth:`score` of every particle's candidate pairs, the landmarks read from pool rows.

        Args:
            pose: (M, 3) poses; z: (B, dim) and r: (B, dim, dim) observations; mean: (R, dim)
                and cov: (R, dim·dim) landmark values by row (the store's pools); rows: (M, V)
                row of particle m's pair v; index: (V,) observation of pair v; pose_cov:
                (M, 3, 3) or None, as in :meth:`score`.
            with_norm: also return log det(2πZ) (else None).

        Returns:
            (D (M, V), log det(2πZ) (M, V) or None).
        """
        dim = self.dim
        mu = np.take(mean, rows, axis=0)
        sig = np.take(cov, rows, axis=0).reshape(rows.shape + (dim, dim))
        pc = None if pose_cov is None else pose_cov[:, None]
        return self.score(pose[:, None], z[None], r[None], mu, sig, pc, index)

    def update_rows(self, pose, z, r, pi, bi, mean, cov, rows):
        """:meth:`update` of P pairs: particle ``pi`` (P,) of ``pose`` (M, 3), observation ``bi``
        (P,) of ``z`` (B, dim) and ``r`` (B, dim, dim), the landmark at pool ``rows`` (P,) of
        ``mean`` (R, dim) and ``cov`` (R, dim·dim) (the store's pools).

        Returns:
            as :meth:`update`.
        """
        dim = self.dim
        mu = np.take(mean, rows, axis=0)
        sig = np.take(cov, rows, axis=0).reshape(-1, dim, dim)
        return self.update(pose[pi], z[bi], r[bi], mu, sig)

    def proposal_terms(self, x, dx, z, r, pi, bi, mean, cov, rows, residuals=True):
        """Per-pair terms of the FastSLAM 2.0 proposal linearised at the poses x (M, 3), for P
        pairs: particle ``pi`` (P,), observation ``bi`` (P,) of z (B, dim) and r (B, dim, dim),
        landmark at pool ``rows`` (P,) of ``mean`` (R, dim) and ``cov`` (R, dim·dim). With Hₓ,
        Z = GΣGᵀ + R and ν = z − ẑ(x) + Hₓ dx (dx (M, 3): the iterated EKF's shift x − x̂).
        ``residuals``: whether the caller needs ν, Z⁻¹ and Hₓ (a model may then return them
        empty, (0, ...)).

        Returns:
            (HₓᵀZ⁻¹Hₓ (P, 3, 3), HₓᵀZ⁻¹ν (P, 3), νᵀZ⁻¹ν (P,), dim·log 2π + log|Z| (P,),
            ν (P, dim), Z⁻¹ (P, dim, dim), Hₓ (P, dim, 3)); ν, Z and Hₓ in any frame the model
            chooses, the same for all three.
        """
        dim = self.dim
        mu = np.take(mean, rows, axis=0)
        sig = np.take(cov, rows, axis=0).reshape(-1, dim, dim)
        x, dx, z, r = x[pi], dx[pi], z[bi], r[bi]
        zhat, g = self.predict(x, mu)
        zinv, zdet = sym_inv_det(g @ sig @ _t(g) + r)
        hx = self.pose_jacobian(x, mu)
        nu = self.innovation(z, zhat) + (hx @ dx[..., None])[..., 0]
        hz = _t(hx) @ zinv  # (P, 3, dim)
        return (hz @ hx, (hz @ nu[..., None])[..., 0], quad_form(nu, zinv), self.dim * LOG_2PI + np.log(zdet),
                nu, zinv, hx)

    def update(self, pose, z, r, mu, sig):
        """EKF update (eqs. 6–11, Joseph form) of P chosen landmark/observation pairs.

        Args:
            pose: (P, 3); z: (P, dim); r: (P, dim, dim); mu: (P, dim); sig: (P, dim, dim).

        Returns:
            (new mean (P, dim), new covariance (P, dim, dim), D (P,), log det(2πZ) (P,)).
        """
        zhat, g = self.predict(pose, mu)
        zmat = g @ sig @ _t(g) + r
        zinv, zdet = sym_inv_det(zmat)
        nu = self.innovation(z, zhat)
        gain = sig @ _t(g) @ zinv
        new_mu = mu + (gain @ nu[..., None])[..., 0]
        ikg = np.eye(self.dim) - gain @ g
        new_sig = ikg @ sig @ _t(ikg) + gain @ r @ _t(gain)
        new_sig = 0.5 * (new_sig + _t(new_sig))
        return new_mu, new_sig, quad_form(nu, zinv), self.dim * LOG_2PI + np.log(zdet)


class StereoPointModel(ObservationModel):
    """A 3D point measured in base_link (x forward, y left, z up) by a stereo camera.

    g(x, l) = Rz(θ)ᵀ · (l − (x, y, 0)): the robot moves in the plane, the point keeps its height.
    The measurement covariance comes with each observation (R = J·Rsp·Jᵀ of eq. 12, moved into
    base_link by the frontend). G = Rz(θ)ᵀ is a rotation, so G⁻¹ = Rz(θ), a new landmark's
    covariance G⁻¹ R G⁻ᵀ is R rotated into the map, and the EKF can run in the map frame with
    H = I: Z = G(Σ + GᵀRG)Gᵀ has the same determinant and Mahalanobis distance as
    S = Σ + Rz R Rzᵀ with the innovation g⁻¹(x, z) − μ. That form needs no 3×3 products per
    candidate, which is what makes the filter step fast.
    """

    dim = 3
    name = "stereo_point"

    def predict(self, pose: np.ndarray, landmark: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        c, s = np.cos(pose[..., 2]), np.sin(pose[..., 2])
        dx = landmark[..., 0] - pose[..., 0]
        dy = landmark[..., 1] - pose[..., 1]
        zhat = np.stack(np.broadcast_arrays(c * dx + s * dy, -s * dx + c * dy, landmark[..., 2]), -1)
        return zhat, _t(self._rot(np.broadcast_to(pose[..., 2], zhat.shape[:-1])))

    @staticmethod
    def to_map(pose: np.ndarray, z: np.ndarray) -> np.ndarray:
        """g⁻¹(x, z): the measured point in the map frame, (..., 3)."""
        c, s = np.cos(pose[..., 2]), np.sin(pose[..., 2])
        lx = pose[..., 0] + c * z[..., 0] - s * z[..., 1]
        ly = pose[..., 1] + s * z[..., 0] + c * z[..., 1]
        return np.stack(np.broadcast_arrays(lx, ly, z[..., 2]), -1)

    def inverse(self, pose: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lm = self.to_map(pose, z)
        return lm, self._rot(np.broadcast_to(pose[..., 2], lm.shape[:-1]))

    def new_landmark(self, pose, z, r):
        """g⁻¹(x, z) and Rz R Rzᵀ from :func:`~mrslam_core.slam.stereo_kernels.observation_terms`
        (the terms the gate uses), each pair its own particle with one observation."""
        lead = np.broadcast_shapes(pose.shape[:-1], z.shape[:-1], r.shape[:-2])
        pose = np.ascontiguousarray(np.broadcast_to(pose, lead + (3,)).reshape(-1, 3), float)
        n = pose.shape[0]
        z = np.ascontiguousarray(np.broadcast_to(z, lead + (3,)).reshape(n, 1, 3), float)
        r = np.ascontiguousarray(np.broadcast_to(r, lead + (3, 3)).reshape(n, 1, 3, 3), float)
        lm, rn = np.empty((n, 1, 3)), np.empty((n, 1, 6))
        stereo_kernels.observation_terms(pose, np.cos(pose[:, 2]), np.sin(pose[:, 2]), z, r, lm, rn)
        return lm.reshape(lead + (3,)), rn[:, 0, [0, 1, 2, 1, 3, 4, 2, 4, 5]].reshape(lead + (3, 3))

    def new_landmark_rows(self, pose, z, r, pi, bi):
        """:meth:`new_landmark` of P pairs in one pass (:func:`~mrslam_core.slam.stereo_kernels.new_points`)."""
        pose = np.ascontiguousarray(pose[pi], float)
        n = pose.shape[0]
        lm, cov = np.empty((n, 3)), np.empty((n, 9))
        stereo_kernels.new_points(pose, np.cos(pose[:, 2]), np.sin(pose[:, 2]), np.ascontiguousarray(z, float),
                                  np.ascontiguousarray(r, float), np.ascontiguousarray(bi, np.int64), lm, cov)
        return lm, cov.reshape(n, 3, 3)

    def pose_jacobian(self, pose: np.ndarray, landmark: np.ndarray) -> np.ndarray:
        zhat, _ = self.predict(pose, landmark)
        c, s = np.cos(pose[..., 2]), np.sin(pose[..., 2])
        jac = np.zeros(zhat.shape + (3,))
        jac[..., 0, 0] = -c
        jac[..., 0, 1] = -s
        jac[..., 1, 0] = s
        jac[..., 1, 1] = -c
        jac[..., 0, 2] = zhat[..., 1]
        jac[..., 1, 2] = -zhat[..., 0]
        return jac

    def score(self, pose, z, r, mu, sig, pose_cov=None, index=None):
        if index is not None:
            z, r = z[..., index, :], r[..., index, :, :]
        shapes = [pose.shape[:-1], z.shape[:-1], r.shape[:-2], mu.shape[:-1], sig.shape[:-2]]
        if pose_cov is not None:
            shapes.append(pose_cov.shape[:-2])
        lead = np.broadcast_shapes(*shapes)
        n = int(np.prod(lead, dtype=np.int64))
        pose, z, mu = (np.broadcast_to(a, lead + (3,)).reshape(n, 3) for a in (pose, z, mu))
        r, sig = (np.broadcast_to(a, lead + (3, 3)).reshape(n, 3, 3) for a in (r, sig))
        if pose_cov is not None:
            pose_cov = np.broadcast_to(pose_cov, lead + (3, 3)).reshape(n, 3, 3)
        # every pair its own particle with one observation and one candidate
        maha, norm = self.score_rows(pose, z[:, None], r[:, None], mu, sig.reshape(n, 9), np.arange(n)[:, None],
                                     np.zeros(1, np.int64), pose_cov, per_particle=True)
        return maha.reshape(lead), norm.reshape(lead)

    def score_rows(self, pose, z, r, mean, cov, rows, index, pose_cov=None, with_norm=True, per_particle=False):
        """The gate in one pass over the pools (:func:`~mrslam_core.slam.stereo_kernels.gate`):
        the observations in the map frame and Rz R Rzᵀ per (particle, observation), then per
        pair S = Σ + Rz R Rzᵀ [+ J P Jᵀ], D and det S from the six distinct terms of S. With
        ``per_particle``, z (M, B, 3) and r (M, B, 3, 3) are each particle's own."""
        m = pose.shape[0]
        pose = np.ascontiguousarray(pose, float)
        zz = np.ascontiguousarray(z if per_particle else z[None], float)
        lm, rn = np.empty((m, zz.shape[1], 3)), np.empty((m, zz.shape[1], 6))
        stereo_kernels.observation_terms(
            pose, np.cos(pose[:, 2]), np.sin(pose[:, 2]), zz,
            np.ascontiguousarray(r if per_particle else r[None], float), lm, rn,
        )
        pc = np.zeros((0, 6))
        if pose_cov is not None:
            pc = np.ascontiguousarray(pose_cov.reshape(m, 9)[:, [0, 1, 2, 4, 5, 8]], float)
        maha = np.empty(rows.shape)
        det = np.empty(rows.shape)
        stereo_kernels.gate(lm, rn, pose, pc, mean, cov,
                            np.ascontiguousarray(rows, np.int64), np.ascontiguousarray(index, np.int64), maha, det)
        if not with_norm:
            return maha, None
        with np.errstate(divide="ignore", invalid="ignore"):
            return maha, 3 * LOG_2PI + np.log(det)

    def update(self, pose, z, r, mu, sig):
        """The Kalman step with H = I in the map frame (see the class docstring), written out on
        the distinct terms of the symmetric matrices (:func:`~mrslam_core.slam.stereo_kernels.kalman`):
        S = Σ + Rz R Rzᵀ, A = S⁻¹ (cofactors), T = Σ A, μ' = μ + T ν, Σ' = Σ − T Σ with
        ν = g⁻¹(x, z) − μ."""
        lead = np.broadcast_shapes(pose.shape[:-1], z.shape[:-1], mu.shape[:-1], sig.shape[:-2], r.shape[:-2])
        pose, z, mu = (np.broadcast_to(a, lead + (3,)).reshape(-1, 3) for a in (pose, z, mu))
        sig, r = (np.broadcast_to(a, lead + (3, 3)).reshape(-1, 3, 3) for a in (sig, r))
        n = pose.shape[0]
        pairs = np.arange(n)
        new_mu, new_sig, maha, norm = self.update_rows(
            pose, z, r, pairs, pairs, np.ascontiguousarray(mu), np.ascontiguousarray(sig).reshape(n, 9), pairs
        )
        return new_mu.reshape(lead + (3,)), new_sig.reshape(lead + (3, 3)), maha.reshape(lead), norm.reshape(lead)

    def update_rows(self, pose, z, r, pi, bi, mean, cov, rows):
        """:meth:`update` of P pairs indexed into per-particle poses and per-observation z and r,
        the landmarks read from pool ``rows`` (no gathered copies; see the base class)."""
        pose = np.ascontiguousarray(pose, float)
        n = rows.size
        new_mu, new_sig, maha, det = np.empty((n, 3)), np.empty((n, 9)), np.empty(n), np.empty(n)
        stereo_kernels.kalman(
            pose, np.cos(pose[:, 2]), np.sin(pose[:, 2]), np.ascontiguousarray(z, float),
            np.ascontiguousarray(r, float), np.ascontiguousarray(pi, np.int64), np.ascontiguousarray(bi, np.int64),
            mean, cov, np.ascontiguousarray(rows, np.int64), new_mu, new_sig, maha, det,
        )
        with np.errstate(divide="ignore", invalid="ignore"):
            return new_mu, new_sig.reshape(n, 3, 3), maha, 3 * LOG_2PI + np.log(det)

    def proposal_terms(self, x, dx, z, r, pi, bi, mean, cov, rows, residuals=True):
        """In the map frame (:func:`~mrslam_core.slam.stereo_kernels.proposal_terms`): ν, Z and Hₓ
        rotated by Rz(θ), which leaves HₓᵀZ⁻¹Hₓ, HₓᵀZ⁻¹ν, νᵀZ⁻¹ν and |Z| unchanged; without
        ``residuals`` they are (0, ...)."""
        x = np.ascontiguousarray(x, float)
        n = rows.size
        kept = n if residuals else 0
        info, zinv, hx = np.empty((n, 3, 3)), np.empty((kept, 3, 3)), np.empty((kept, 3, 3))
        eta, nu = np.empty((n, 3)), np.empty((kept, 3))
        quad, det = np.empty(n), np.empty(n)
        stereo_kernels.proposal_terms(
            x, np.ascontiguousarray(dx, float), np.cos(x[:, 2]), np.sin(x[:, 2]), np.ascontiguousarray(z, float),
            np.ascontiguousarray(r, float), np.ascontiguousarray(pi, np.int64), np.ascontiguousarray(bi, np.int64),
            mean, cov, np.ascontiguousarray(rows, np.int64), info, eta, quad, det, nu, zinv, hx,
        )
        with np.errstate(divide="ignore", invalid="ignore"):
            norm = 3 * LOG_2PI + np.log(det)
        return info, eta, quad, norm, nu, zinv, hx

    @staticmethod
    def _rot(theta: np.ndarray) -> np.ndarray:
        c, s = np.cos(theta), np.sin(theta)
        rot = np.zeros(np.shape(theta) + (3, 3))
        rot[..., 0, 0] = c
        rot[..., 0, 1] = -s
        rot[..., 1, 0] = s
        rot[..., 1, 1] = c
        rot[..., 2, 2] = 1.0
        return rot


class RangeBearingModel(ObservationModel):
    """A 2D landmark measured as (range [m], bearing [rad]) from base_link (bearing from x, CCW)."""

    dim = 2
    name = "range_bearing"

    def predict(self, pose: np.ndarray, landmark: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        dx = landmark[..., 0] - pose[..., 0]
        dy = landmark[..., 1] - pose[..., 1]
        q = np.maximum(dx * dx + dy * dy, 1e-12)
        r = np.sqrt(q)
        zhat = np.stack([r, wrap_angle(np.arctan2(dy, dx) - pose[..., 2])], -1)
        g = np.empty(zhat.shape[:-1] + (2, 2))
        g[..., 0, 0] = dx / r
        g[..., 0, 1] = dy / r
        g[..., 1, 0] = -dy / q
        g[..., 1, 1] = dx / q
        return zhat, g

    def innovation(self, z: np.ndarray, zhat: np.ndarray) -> np.ndarray:
        nu = z - zhat
        nu[..., 1] = wrap_angle(nu[..., 1])
        return nu

    def pose_jacobian(self, pose: np.ndarray, landmark: np.ndarray) -> np.ndarray:
        dx = landmark[..., 0] - pose[..., 0]
        dy = landmark[..., 1] - pose[..., 1]
        q = np.maximum(dx * dx + dy * dy, 1e-12)
        r = np.sqrt(q)
        jac = np.zeros(dx.shape + (2, 3))
        jac[..., 0, 0] = -dx / r
        jac[..., 0, 1] = -dy / r
        jac[..., 1, 0] = dy / q
        jac[..., 1, 1] = -dx / q
        jac[..., 1, 2] = -1.0
        return jac

    def inverse(self, pose: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a = pose[..., 2] + z[..., 1]
        c, s = np.cos(a), np.sin(a)
        lm = np.stack(np.broadcast_arrays(pose[..., 0] + z[..., 0] * c, pose[..., 1] + z[..., 0] * s), -1)
        ginv = np.empty(lm.shape[:-1] + (2, 2))
        ginv[..., 0, 0] = c
        ginv[..., 0, 1] = -z[..., 0] * s
        ginv[..., 1, 0] = s
        ginv[..., 1, 1] = z[..., 0] * c
        return lm, ginv


MODELS: dict[str, type[ObservationModel]] = {m.name: m for m in (StereoPointModel, RangeBearingModel)}


def make_model(name: str) -> ObservationModel:
    """The observation model called ``name`` (a key of :data:`MODELS`)."""
    try:
        return MODELS[name]()
    except KeyError:
        raise ValueError(f"unknown observation model {name!r}; have {sorted(MODELS)}") from None
