"""Observation models: how a landmark in the map appears to a robot at an SE(2) pose.

The filter only calls :meth:`score` (Mahalanobis distances and normalisers for many
particle/observation/candidate triples) and :meth:`update` (the EKF step, eqs. 6–11, for the chosen
pairs) and :meth:`inverse` (new landmarks), so any model with this interface plugs in. Poses are
(x [m], y [m], θ [rad]) of base_link in the map frame; all methods broadcast over leading axes.
"""

from __future__ import annotations

import numpy as np

from mrslam_core.geometry.se2 import wrap_angle
from mrslam_core.linalg import inv_quad_det, quad_form, rotate_z_sym3, sym3_kalman, sym_inv_det

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
        return self.to_map(pose, z), rotate_z_sym3(r, pose[..., 2])

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
        if pose_cov is not None:
            return super().score(pose, z, r, mu, sig, pose_cov, index)
        # the observation in the map and its covariance there depend on (particle, observation)
        # only: compute them for (M, B) and spread them over the V candidate pairs
        lm = self.to_map(pose, z)
        r_map = rotate_z_sym3(r, pose[..., 2])
        if index is not None:
            lm, r_map = lm[..., index, :], r_map[..., index, :, :]
        maha, sdet = inv_quad_det(sig + r_map, lm - mu)
        return maha, 3 * LOG_2PI + np.log(sdet)

    def update(self, pose, z, r, mu, sig):
        lm = self.to_map(pose, z)
        shift, new_sig, maha, sdet = sym3_kalman(sig, sig + rotate_z_sym3(r, pose[..., 2]), lm - mu)
        return mu + shift, new_sig, maha, 3 * LOG_2PI + np.log(sdet)

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
