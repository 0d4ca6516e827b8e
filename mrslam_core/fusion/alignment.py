"""Pairwise 2D alignment of two landmark maps (004 section 3): descriptor matches, RANSAC on a
rigid planar transform, least-squares refinement on the inliers, and an accept/reject decision.

The transform (tx [m], ty [m], θ [rad]) maps SOURCE map points into the TARGET map:
``p_target = R(θ)·p_source + t``. Alignment is planar even for 3D maps (the robots move in the
xy plane, 004 eq. 1); z is ignored here.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from mrslam_core.fusion.config import FusionConfig
from mrslam_core.fusion.maps import FusionError, LandmarkMap
from mrslam_core.geometry.se2 import wrap_angle


class MatchSplit:
    """The inlier / outlier split of an alignment's descriptor matches (``matches``: (P, 2)
    (target row, source row); ``inliers``: indices into it)."""

    matches: np.ndarray
    inliers: np.ndarray

    @property
    def inlier_pairs(self) -> np.ndarray:
        """(I, 2) (target row, source row) of the inliers."""
        return self.matches[self.inliers]

    @property
    def outlier_pairs(self) -> np.ndarray:
        """(P − I, 2) matches that are not inliers."""
        mask = np.ones(len(self.matches), bool)
        mask[self.inliers] = False
        return self.matches[mask]


@dataclass(frozen=True)
class Alignment(MatchSplit):
    """The outcome of aligning a source map to a target map.

    Attributes:
        transform: (3,) source → target (tx [m], ty [m], θ [rad]); NaN when no hypothesis exists.
        matches: (P, 2) int64 descriptor matches as (target row, source row).
        inliers: (I,) int64 indices into ``matches`` of the RANSAC inliers.
        rmse: planar RMSE of the inliers' residuals after refinement [m] (NaN without inliers).
        spread: RMS distance of the inlier target landmarks from their centroid [m].
        accepted: whether the alignment passed every check of the config.
        reason: why it was rejected (empty when accepted), in words for the log.
        cov: (3, 3) covariance of the transform from the inliers' residuals (Gauss-Newton,
            σ² (JᵀJ)⁻¹ with σ² = Σ‖r‖² / (2I − 3)); NaN without three inliers.
    """

    transform: np.ndarray
    matches: np.ndarray
    inliers: np.ndarray
    rmse: float
    spread: float
    accepted: bool
    reason: str = ""
    cov: np.ndarray = field(default_factory=lambda: np.full((3, 3), np.nan))


def rigid_transform_2d(src: np.ndarray, dst: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Closed-form weighted least-squares rigid motion with dst ≈ R(θ)·src + t.

    Minimises Σ wᵢ‖R·sᵢ + t − dᵢ‖² over (t, θ): with centred points s', d' (weighted centroids
    s̄, d̄), θ = atan2(Σ w (s'ₓd'ᵧ − s'ᵧd'ₓ), Σ w (s'ₓd'ₓ + s'ᵧd'ᵧ)) and t = d̄ − R·s̄.

    Args:
        src, dst: (..., N, 2 or 3) matched points [m] (only x, y are used), N >= 2.
        weights: (..., N) non-negative weights (default 1).

    Returns:
        (..., 3) transform (tx, ty, θ).
    """
    src = np.asarray(src, float)[..., :2]
    dst = np.asarray(dst, float)[..., :2]
    if src.shape != dst.shape or src.shape[-2] < 2:
        raise FusionError(f"need matching (..., N >= 2, 2) point sets, got {src.shape} and {dst.shape}")
    w = np.ones(src.shape[:-1]) if weights is None else np.broadcast_to(np.asarray(weights, float), src.shape[:-1])
    wsum = w.sum(-1, keepdims=True)
    s_bar = (w[..., None] * src).sum(-2) / wsum
    d_bar = (w[..., None] * dst).sum(-2) / wsum
    s = src - s_bar[..., None, :]
    d = dst - d_bar[..., None, :]
    sin = (w * (s[..., 0] * d[..., 1] - s[..., 1] * d[..., 0])).sum(-1)
    cos = (w * (s[..., 0] * d[..., 0] + s[..., 1] * d[..., 1])).sum(-1)
    theta = np.arctan2(sin, cos)
    c, sn = np.cos(theta), np.sin(theta)
    tx = d_bar[..., 0] - (c * s_bar[..., 0] - sn * s_bar[..., 1])
    ty = d_bar[..., 1] - (sn * s_bar[..., 0] + c * s_bar[..., 1])
    return np.stack([tx, ty, theta], -1)


def transform_jacobian(transform: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Jacobian (..., N, 2, 3) of R(θ)·p + t with respect to (tx, ty, θ) at points (..., N, 2+)
    [m]: [I₂ | ∂R/∂θ·p] (translation at the source origin)."""
    t = np.asarray(transform, float)
    pts = np.asarray(pts, float)
    c = np.cos(t[..., 2])[..., None]
    s = np.sin(t[..., 2])[..., None]
    jac = np.zeros(pts.shape[:-1] + (2, 3))
    jac[..., 0, 0] = jac[..., 1, 1] = 1.0
    jac[..., 0, 2] = -s * pts[..., 0] - c * pts[..., 1]
    jac[..., 1, 2] = c * pts[..., 0] - s * pts[..., 1]
    return jac


def transform_covariance(transform: np.ndarray, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Covariance (3, 3) of a fitted transform (tx, ty, θ) from its N >= 2 residuals.

    The residuals rᵢ = R·sᵢ + t − dᵢ have Jacobian Jᵢ = [I₂ | ∂R/∂θ·sᵢ]; with the residual
    variance σ² = Σ‖rᵢ‖² / (2N − 3), Cov = σ² (JᵀJ)⁻¹ (translation at the source origin, so
    it grows with the lever arm of the landmarks). N = 2 (no redundancy) gives NaN.
    """
    src = np.asarray(src, float)[:, :2]
    dst = np.asarray(dst, float)[:, :2]
    n = src.shape[0]
    if n < 2 or 2 * n - 3 <= 0:
        return np.full((3, 3), np.nan)
    res = apply_transform(transform, src) - dst
    sigma2 = float((res**2).sum() / (2 * n - 3))
    jac = transform_jacobian(transform, src)
    jtj = np.einsum("nki,nkj->ij", jac, jac)
    return sigma2 * np.linalg.inv(jtj)


def transform_cramer_rao(transform: np.ndarray, src: np.ndarray, sigma: float) -> np.ndarray:
    """Cramér–Rao covariance (3, 3) of (tx, ty, θ) fitted to N correct matches whose source points
    are ``src`` (N, 2+) [m], when both maps hold each point with isotropic noise σ [m] per
    coordinate: each residual R·s + t − d has covariance 2σ²I, so C = 2σ² (JᵀJ)⁻¹ with J as in
    :func:`transform_covariance` (translation at the source origin). The least-squares fit is
    the maximum-likelihood estimate for this noise, so its error e should give eᵀC⁻¹e ~ χ²(3)."""
    jac = transform_jacobian(transform, np.asarray(src, float)[:, :2])
    return 2 * sigma**2 * np.linalg.inv(np.einsum("nki,nkj->ij", jac, jac))


def transform_information_covariance(
    transform: np.ndarray, src: np.ndarray, cov_src: np.ndarray, cov_dst: np.ndarray
) -> np.ndarray:
    """Cramér–Rao covariance (3, 3) of (tx, ty, θ) from N >= 2 correct matches whose landmarks
    carry their own covariances: residual rᵢ = R·sᵢ + t − dᵢ has covariance
    Sᵢ = Σ_dst,i + R·Σ_src,i·Rᵀ (x, y block), so C = (Σ Jᵢᵀ Sᵢ⁻¹ Jᵢ)⁻¹ (the general form of
    :func:`transform_cramer_rao`; translation at the source origin).

    Args:
        transform: (3,) source → target.
        src: (N, 2+) source points [m]; cov_src, cov_dst: (N, 2+, 2+) their covariances [m²].
    """
    src = np.asarray(src, float)[:, :2]
    c, s = np.cos(transform[2]), np.sin(transform[2])
    r = np.array([[c, -s], [s, c]])
    cov = np.asarray(cov_dst, float)[:, :2, :2] + r @ np.asarray(cov_src, float)[:, :2, :2] @ r.T
    jac = transform_jacobian(transform, src)
    info = np.einsum("nki,nkl,nlj->ij", jac, np.linalg.inv(cov), jac)
    return np.linalg.inv(info)


def apply_transform(transform: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Planar points (..., N, 2+) moved by transforms (..., 3); returns (..., N, 2)."""
    t = np.asarray(transform, float)
    pts = np.asarray(pts, float)
    c = np.cos(t[..., 2])[..., None]
    s = np.sin(t[..., 2])[..., None]
    x = t[..., 0, None] + c * pts[..., 0] - s * pts[..., 1]
    y = t[..., 1, None] + s * pts[..., 0] + c * pts[..., 1]
    return np.stack([x, y], -1)


def explained(transform: np.ndarray, target: LandmarkMap, source: LandmarkMap, matches: np.ndarray,
              distance: float, gate: float = 0.0, floor: float = 0.0) -> np.ndarray:
    """(P,) bool: the descriptor ``matches`` (P, 2) (target row, source row) whose source landmark,
    moved by ``transform`` (3,), lands within ``distance`` [m] of its target landmark (planar).

    With ``gate`` > 0 the test is instead the planar Mahalanobis distance
    rᵀ(R Σ_src Rᵀ + Σ_tgt + floor² I)⁻¹r <= ``gate`` (a chi-square quantile, 2 dof), r the
    residual [m], so a pose a few degrees off stops explaining a stereo point 2 m away whose
    lateral error is a few cm, where a 0.3 m distance still counts it.
    """
    matches = np.asarray(matches, np.int64).reshape(-1, 2)
    moved = apply_transform(transform, source.means[matches[:, 1], :2])
    res = moved - target.means[matches[:, 0], :2]
    if gate <= 0:
        return np.linalg.norm(res, axis=1) <= distance
    c, s = np.cos(transform[2]), np.sin(transform[2])
    rot = np.array([[c, -s], [s, c]])
    cov = (target.covs[matches[:, 0], :2, :2] + rot @ source.covs[matches[:, 1], :2, :2] @ rot.T
           + floor**2 * np.eye(2))
    return np.einsum("ni,ni->n", res, np.linalg.solve(cov, res[..., None])[..., 0]) <= gate


def match_descriptors(
    target: np.ndarray, source: np.ndarray, max_sq_dist: float, mutual: bool = True
) -> np.ndarray:
    """Nearest-neighbour descriptor matches (kd-tree over the target's descriptors).

    Args:
        target: (Nt, D) descriptors of the target map.
        source: (Ns, D) descriptors of the source map.
        max_sq_dist: E0, largest squared Euclidean distance of a match (000 eq. 16).
        mutual: keep a pair only when each is the other's nearest neighbour.

    Returns:
        (P, 2) int64 (target row, source row), sorted by source row.
    """
    target = np.asarray(target, float)
    source = np.asarray(source, float)
    if len(target) == 0 or len(source) == 0 or target.shape[1] != source.shape[1]:
        if len(target) and len(source) and target.shape[1] != source.shape[1]:
            raise FusionError(f"descriptor lengths differ: {target.shape[1]} vs {source.shape[1]}")
        return np.zeros((0, 2), np.int64)
    bound = np.sqrt(max_sq_dist) + 1e-9
    d_st, i_st = cKDTree(target).query(source, k=1, distance_upper_bound=bound)
    ok = np.isfinite(d_st)
    src_rows = np.flatnonzero(ok)
    tgt_rows = i_st[ok]
    if mutual and src_rows.size:
        _, i_ts = cKDTree(source).query(target[tgt_rows], k=1)
        keep = i_ts == src_rows
        src_rows, tgt_rows = src_rows[keep], tgt_rows[keep]
    return np.column_stack([tgt_rows, src_rows]).astype(np.int64)


def _pair_weights(target: LandmarkMap, source: LandmarkMap, pairs: np.ndarray, weighted: bool) -> np.ndarray:
    if not weighted:
        return np.ones(len(pairs))
    var = np.trace(target.covs[pairs[:, 0], :2, :2], axis1=1, axis2=2)
    var += np.trace(source.covs[pairs[:, 1], :2, :2], axis1=1, axis2=2)
    return 1.0 / np.maximum(var, 1e-12)


def ransac_align(
    target: LandmarkMap, source: LandmarkMap, config: FusionConfig, matches: np.ndarray | None = None
) -> Alignment:
    """Align ``source`` to ``target`` by RANSAC over descriptor matches (004 section 3).

    Each hypothesis is the exact rigid transform of two random matches; its cost is the
    truncated squared residual Σ min(e², d²) over all matches (MSAC, d = inlier distance). The
    best hypothesis's inliers are refitted by weighted least squares (:func:`rigid_transform_2d`)
    and recomputed ``refine_iterations`` times. The result is accepted when it has at least
    ``min_inliers`` inliers, an RMSE of at most ``max_residual`` and a spread of at least
    ``min_spread``; otherwise ``reason`` says which check failed.

    Args:
        target, source: the two maps, each in its own frame.
        config: thresholds.
        matches: (P, 2) (target row, source row) to use instead of descriptor matching.
    """
    cfg = config
    if matches is None:
        matches = match_descriptors(target.descriptors, source.descriptors, cfg.descriptor_threshold, cfg.mutual)
    matches = np.asarray(matches, np.int64).reshape(-1, 2)
    p = len(matches)
    nan = np.full(3, np.nan)
    none = np.zeros(0, np.int64)
    if p < max(cfg.min_inliers, 2):
        return Alignment(nan, matches, none, float("nan"), 0.0, False,
                         f"only {p} descriptor matches between {len(target)} and {len(source)} "
                         f"landmarks (need at least {cfg.min_inliers}): the maps do not overlap")
    dst = target.means[matches[:, 0], :2]
    src = source.means[matches[:, 1], :2]
    w = _pair_weights(target, source, matches, cfg.weighted)
    d2 = cfg.inlier_distance**2

    rng = np.random.default_rng(cfg.seed)
    n_hyp = cfg.ransac_iterations
    a = rng.integers(p, size=n_hyp)
    b = (a + rng.integers(1, p, size=n_hyp)) % p
    idx = np.stack([a, b], 1)
    hyp = rigid_transform_2d(src[idx], dst[idx])  # (H, 3)
    # a rigid motion keeps distances: pairs whose separation differs between maps cannot be right
    sep_src = np.linalg.norm(src[a] - src[b], axis=1)
    sep_dst = np.linalg.norm(dst[a] - dst[b], axis=1)
    valid = (sep_src > 1e-9) & (np.abs(sep_src - sep_dst) <= 2 * cfg.inlier_distance)
    cost = np.full(n_hyp, np.inf)
    if valid.any():
        err2 = ((apply_transform(hyp[valid], src[None]) - dst[None]) ** 2).sum(-1)  # (H', P)
        cost[valid] = np.minimum(err2, d2).sum(-1)
    if not np.isfinite(cost).any():
        return Alignment(nan, matches, none, float("nan"), 0.0, False,
                         f"no rigid hypothesis from {p} descriptor matches: no two matches keep "
                         f"their separation within {2 * cfg.inlier_distance:.2f} m")
    best = hyp[int(np.argmin(cost))]
    inl = np.flatnonzero(((apply_transform(best, src) - dst) ** 2).sum(-1) <= d2)
    for _ in range(cfg.refine_iterations):
        if inl.size < 2:
            break
        best = rigid_transform_2d(src[inl], dst[inl], w[inl])
        new = np.flatnonzero(((apply_transform(best, src) - dst) ** 2).sum(-1) <= d2)
        if np.array_equal(new, inl):
            break
        inl = new
    if inl.size >= 2:
        best = rigid_transform_2d(src[inl], dst[inl], w[inl])
    best = np.array([best[0], best[1], float(wrap_angle(best[2]))])
    res = np.linalg.norm(apply_transform(best, src[inl]) - dst[inl], axis=1)
    rmse = float(np.sqrt(np.mean(res**2))) if inl.size else float("nan")
    spread = float(np.sqrt(((dst[inl] - dst[inl].mean(0)) ** 2).sum(1).mean())) if inl.size else 0.0
    reason = ""
    if inl.size < cfg.min_inliers:
        reason = (f"{inl.size} inliers of {p} descriptor matches within {cfg.inlier_distance:.2f} m "
                  f"(need {cfg.min_inliers}): no consistent overlap")
    elif not rmse <= cfg.max_residual:
        reason = f"inlier RMSE {rmse:.3f} m exceeds {cfg.max_residual:.3f} m"
    elif spread < cfg.min_spread:
        reason = (f"the {inl.size} inliers lie within {spread:.3f} m of their centroid "
                  f"(need {cfg.min_spread:.3f} m): rotation undetermined")
    cov = transform_covariance(best, src[inl], dst[inl]) if inl.size >= 2 else np.full((3, 3), np.nan)
    return Alignment(best, matches, inl, rmse, spread, reason == "", reason, cov)


def alignment_error(estimate: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """(translation error [m], |rotation error| [rad]) between two transforms (3,)."""
    e = np.asarray(estimate, float)
    t = np.asarray(truth, float)
    return float(np.hypot(e[0] - t[0], e[1] - t[1])), float(abs(wrap_angle(e[2] - t[2])))
