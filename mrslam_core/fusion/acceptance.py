"""When a robot with an unknown start may join the common filter (issue 28): statistical tests
instead of metre thresholds.

A join puts robot i, mapped in its own frame, into the common frame by a transform T (local →
common, (tx [m], ty [m], θ [rad])). Its evidence is a map alignment (descriptor matches between
the two maps) or a rendezvous (a mutual sighting with a robot of the common filter). Three tests:

1. **Geometric consistency** (:func:`chi2_align`). Each matched landmark pair (c in the common
   map, l in the local one) leaves the residual rᵢ = R·lᵢ + t − cᵢ with covariance
   Sᵢ = Σ_c,i + R·Σ_l,i·Rᵀ + u²I, both Σ the landmark's marginal covariance in its own filter (the
   particles' mixture, :func:`marginal_landmarks`: the per-particle EKF covariance plus the spread
   of the particles' means, i.e. the part of the robot's path uncertainty its map inherits) and
   u² one planar variance [m²] shared by every pair: what the maps' covariances leave out. A
   collapsed particle cloud keeps almost none of the path uncertainty, so a young stereo map's
   landmarks are placed relative to each other far less well than their covariances say (the
   test_central world at its join: residuals 0.06–0.14 m against the simulator's truth where the
   covariances give σ 0.009–0.079 m, NEES 4–401, median 185 for 2 dof; the residual does not
   grow with Σ, so the missing part is added, not a scale). u² is estimated with T: the RANSAC
   hypothesis and u² together by maximum likelihood of a contaminated normal over every match (a
   match is right with probability 1 − ε and then rᵢ ~ N(0, Sᵢ + Jᵢ·Cov T·Jᵢᵀ), or wrong and
   uniform over the target map's extent A; ε by EM; u² from a grid), then at each refinement
   the same way at the fitted T (rᵢ ~ N(0, Sᵢ) for a right match; u² continuous). It is 0 when the maps explain their residuals (MR.CLAM's barcode maps, reduced χ² 0.015–0.1). A pair is an
   inlier when rᵢᵀ(Sᵢ + Jᵢ·Cov T·Jᵢᵀ)⁻¹rᵢ ≤ χ²₂(p), Jᵢ = ∂rᵢ/∂T (the transform's own
   uncertainty: from the two pairs of a RANSAC hypothesis, then from the fit). The transform is
   the generalised least-squares fit on the inliers (Gauss-Newton with the full Sᵢ⁻¹), and the
   alignment is consistent when
     - Σ rᵢᵀSᵢ⁻¹rᵢ ≤ χ²_{2n−3}(p) over its n inliers (2n residuals, 3 parameters; with u > 0 the
       sum is near 2n by construction, so consistency then rests on every inlier's gate under
       one shared u and on the next test), and
     - the inlier set is not explainable by chance: any two matches fix a transform, so only the
       n − 2 further inliers are evidence. Under a wrong transform a match lands inside its gate
       with probability qᵢ = π χ²₂(p) √det Sᵢ / A (gate ellipse over the target map's extent A), so
       P(≥ n − 2 of the other P − 2 matches by chance) is a binomial tail; with the
       C(P, 2) minimal sets RANSAC may choose from (Bonferroni), it must be ≤ 1 − p. A larger u
       widens every gate, so more inliers are needed.
   Its covariance is Cov T = (Σ Jᵢᵀ Sᵢ⁻¹ Jᵢ)⁻¹, scaled up by the reduced χ² when that exceeds 1.
2. **Absorbable** (:func:`absorbable`). The transform's error moves the joined robot by
   J_T·Cov T·J_Tᵀ =: P_T (at its local pose). A particle join places robot i at T ⊕ xᵢ in every
   particle, so the transform's error is carried only as far as the joined cloud already spreads:
   the joining robot's own pose covariance (moved into the common frame) plus the pose spread with
   which the common filter holds its robots (the frame's own uncertainty), P_ref. With
   e ~ N(0, P_T), E[eᵀP_ref⁻¹e] = tr(P_ref⁻¹P_T); the join is absorbable when that is at most the
   pose's 3 dof, i.e. the transform's error looks, on average, like one more draw of the cloud.
   A larger one would make the newcomer overconfident about a pose the common map cannot yet
   correct, and its observations would drag the shared landmarks (and every robot with them).
   (Drawing each joined particle's transform from N(T, s²·Cov T) and counting s²·P_T into
   P_ref would void the test: tr((P_ref + s²P_T)⁻¹P_T) < 3/s² for every P_ref, so with s = 1 every
   consistent alignment passes.)
3. **Agreement of independent evidence** (:class:`JoinGate`). An alignment that passes 1 and 2 is
   strong and may join alone; a rendezvous sighting, or an alignment that passes 1 but not 2, is
   weak and is held. A robot joins when a new piece of evidence agrees with a held independent
   one (two alignments of the same maps are not independent) within the window: (T₂ − T₁)ᵀ(Cov T₁ + Cov T₂)⁻¹(T₂ − T₁) ≤ χ²₃(p). A strong alignment that
   contradicts held evidence waits too.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.special import comb
from scipy.stats import binom, chi2

from mrslam_core.fusion.alignment import MatchSplit, apply_transform, rigid_transform_2d, transform_jacobian
from mrslam_core.fusion.config import FusionConfig
from mrslam_core.fusion.maps import LandmarkMap
from mrslam_core.geometry.se2 import wrap_angle
from mrslam_core.linalg import quad_form, sym_inv_det
from mrslam_core.slam.filter import MultiRobotFastSLAM


def marginal_landmarks(slam: MultiRobotFastSLAM, slots: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each landmark's marginal over the particles that hold it (weights renormalised):
    mean μ = Σ wₘ μₘ, covariance Σ wₘ (Σₘ + (μₘ − μ)(μₘ − μ)ᵀ).

    Args:
        slam: the filter; slots: (N,) landmark slots at least one particle holds.

    Returns:
        ((N, dim) means [m], (N, dim, dim) covariances [m²]), dim as the store's.
    """
    slots = np.asarray(slots, np.int64)
    m = slam.num_particles
    mean, cov, ex = slam.landmarks.gather(np.arange(m)[:, None], slots[None], ("mean", "cov", "exists"))
    w = np.exp(slam.log_w)[:, None] * ex
    w = w / np.maximum(w.sum(0, keepdims=True), 1e-300)
    mean, cov = mean.astype(float), cov.astype(float)
    mu = np.einsum("ms,msd->sd", w, mean)
    d = mean - mu[None]
    sigma = np.einsum("ms,msij->sij", w, cov) + np.einsum("ms,msi,msj->sij", w, d, d)
    return mu, sigma


def with_marginals(slam: MultiRobotFastSLAM, lmap: LandmarkMap, rows: np.ndarray) -> LandmarkMap:
    """``lmap`` (a map of ``slam``, ``ids`` its slots) with the landmarks at ``rows`` set to their
    marginal means and covariances (planar maps keep z and var z as padded)."""
    rows = np.unique(np.asarray(rows, np.int64))
    means, covs = lmap.means.copy(), lmap.covs.copy()
    if rows.size:
        mu, sigma = marginal_landmarks(slam, lmap.ids[rows])
        dim = mu.shape[1]
        means[rows, :dim] = mu
        covs[rows, :dim, :dim] = sigma
    return LandmarkMap(means, covs, lmap.descriptors, lmap.counts, lmap.ids)


@dataclass(frozen=True)
class GatedAlignment(MatchSplit):
    """A map alignment judged by the χ² tests of this module.

    Attributes:
        transform: (3,) source (local) → target (common) frame; NaN without a hypothesis.
        cov: (3, 3) its covariance (NaN when undetermined).
        matches: (P, 2) descriptor matches (target row, source row).
        inliers: (I,) indices into ``matches`` inside their χ²₂ gate.
        chi2: Σ rᵀS⁻¹r over the inliers (S with u²); dof: 2I − 3.
        chance: probability that I − 2 further matches agree with a wrong transform by chance
            (Bonferroni over the C(P, 2) minimal sets).
        consistent: tests 1 passed (residual χ² and chance); reason: what failed, in words.
        rmse: planar RMSE of the inliers' residuals [m] (for the log).
        unmodelled_sigma: u [m], the planar σ added to every pair's residual covariance for what
            the maps' covariances leave out (0: they explain the residuals).
    """

    transform: np.ndarray
    cov: np.ndarray
    matches: np.ndarray
    inliers: np.ndarray
    chi2: float
    dof: int
    chance: float
    consistent: bool
    reason: str = ""
    rmse: float = float("nan")
    unmodelled_sigma: float = 0.0


def residual_covariances(theta: np.ndarray, cov_t: np.ndarray, cov_s: np.ndarray) -> np.ndarray:
    """S = Σ_t + R(θ)·Σ_s·R(θ)ᵀ (x, y blocks) for rotations θ (...,) and pairs (..., P, 2+, 2+)
    (the pairs' leading axes broadcast against θ's): returns (..., P, 2, 2)."""
    th = np.asarray(theta, float)[..., None]
    c, s = np.cos(th), np.sin(th)
    a, b, o = cov_s[..., 0, 0], cov_s[..., 1, 1], cov_s[..., 0, 1]
    xx = c * c * a - 2 * c * s * o + s * s * b  # R Σ Rᵀ written out, broadcast over θ
    yy = s * s * a + 2 * c * s * o + c * c * b
    xy = c * s * (a - b) + (c * c - s * s) * o
    out = np.empty(xx.shape + (2, 2))
    out[..., 0, 0] = xx + cov_t[..., 0, 0]
    out[..., 1, 1] = yy + cov_t[..., 1, 1]
    out[..., 0, 1] = out[..., 1, 0] = xy + cov_t[..., 0, 1]
    return out


def mahalanobis2(res: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """rᵀS⁻¹r for residuals (..., 2) and covariances (..., 2, 2)."""
    return quad_form(res, sym_inv_det(cov)[0])


def gls_refine(transform: np.ndarray, src: np.ndarray, dst: np.ndarray, cov_s: np.ndarray, cov_t: np.ndarray,
               iterations: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """Generalised least squares of dst ≈ R·src + t with residual covariances S(θ) (Gauss-Newton
    from ``transform``): ((3,) transform, (3, 3) (Σ JᵀS⁻¹J)⁻¹)."""
    t = np.asarray(transform, float).copy()
    info = np.full((3, 3), np.nan)
    for _ in range(iterations):
        s = residual_covariances(t[2], cov_t, cov_s)
        s_inv = np.linalg.inv(s)
        jac = transform_jacobian(t, src)
        res = apply_transform(t, src) - dst
        info = np.einsum("nki,nkl,nlj->ij", jac, s_inv, jac)
        step = np.linalg.solve(info, -np.einsum("nki,nkl,nl->i", jac, s_inv, res))
        t += step
        t[2] = float(wrap_angle(t[2]))
        if np.abs(step).max() < 1e-10:
            break
    s_inv = np.linalg.inv(residual_covariances(t[2], cov_t, cov_s))
    jac = transform_jacobian(t, src)
    info = np.einsum("nki,nkl,nlj->ij", jac, s_inv, jac)
    return t, np.linalg.inv(info)


#: unmodelled variances u² [m²] tried with every RANSAC hypothesis: 0, then 10⁻⁶ … 1 (σ 1 mm … 1 m) in steps of √10
UNMODELLED_GRID = np.concatenate([[0.0], np.logspace(-6.0, 0.0, 13)])


def contaminated_loglik(res: np.ndarray, cov: np.ndarray, area: float, iterations: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """Log-likelihood of residuals under a contaminated normal: each match is right with
    probability 1 − ε (residual ~ N(0, S)) or wrong (uniform over ``area`` [m²]), ε by EM.

    Args:
        res: (..., P, 2) residuals [m]; cov: (..., P, 2, 2) their covariances S [m²].

    Returns:
        ((...) log-likelihood at the EM's ε, (...) ε).
    """
    inv, det = sym_inv_det(cov)
    log_n = -0.5 * quad_form(res, inv) - np.log(2 * np.pi) - 0.5 * np.log(np.maximum(det, 1e-300))
    log_out = -np.log(area)
    eps = np.full(res.shape[:-2], 0.5)
    for _ in range(iterations):
        a = np.log1p(-eps)[..., None] + log_n
        b = np.log(eps)[..., None] + log_out
        w = np.exp(a - np.logaddexp(a, b))  # P(right | residual)
        eps = np.clip(1.0 - w.mean(-1), 1e-6, 1 - 1e-6)
    a = np.log1p(-eps)[..., None] + log_n
    b = np.log(eps)[..., None] + log_out
    return np.logaddexp(a, b).sum(-1), eps


def unmodelled_variance(res: np.ndarray, cov: np.ndarray, area: float) -> float:
    """The planar variance u² [m²] ≥ 0 that, added to every residual's covariance ``cov``
    (P, 2, 2) [m²], makes the residuals ``res`` (P, 2) [m] most likely under
    :func:`contaminated_loglik` (u searched from 0.1 mm to 1 m; 0 when that beats every u > 0).
    Wrong matches count only through ε, so one of them does not inflate u²; for residuals of a
    fit, u² is low by about the share of the fit's parameters (3 of the inliers' 2n coordinates)."""
    eye = np.eye(2)

    def nll(log_v: float) -> float:
        return -float(contaminated_loglik(res, cov + 10.0**log_v * eye, area)[0])

    opt = minimize_scalar(nll, bounds=(-8.0, 0.0), method="bounded", options={"xatol": 1e-3})
    return 0.0 if nll(-np.inf) <= opt.fun else float(10.0**opt.x)


def chi2_align(target: LandmarkMap, source: LandmarkMap, config: FusionConfig, matches: np.ndarray) -> GatedAlignment:
    """Align ``source`` to ``target`` over descriptor ``matches`` (P, 2) (target row, source row)
    by the tests of the module docstring (1): RANSAC over pairs of matches whose separations
    agree (χ²₁, the maps' own covariances); the hypothesis and the unmodelled variance u² of
    :data:`UNMODELLED_GRID` most likely under :func:`contaminated_loglik` (every match, each
    residual with the hypothesis's own uncertainty); then, until the inlier set is stable, the
    χ²₂(p) gates, the GLS fit on the inliers and u² again from every match's residual
    (:func:`unmodelled_variance`).
    Only ``config.join_confidence`` p, ``ransac_iterations`` and ``seed`` are used."""
    p_conf = config.join_confidence
    matches = np.asarray(matches, np.int64).reshape(-1, 2)
    n_m = len(matches)
    nan3, none = np.full(3, np.nan), np.zeros(0, np.int64)

    def refuse(reason: str, t=nan3, inl=none, x2=float("nan"), dof=0, chance=1.0) -> GatedAlignment:
        return GatedAlignment(t, np.full((3, 3), np.nan), matches, inl, x2, dof, chance, False, reason)

    if n_m < 3:
        return refuse(f"only {n_m} descriptor matches: two fix any transform, a third is needed to test it")
    dst, src = target.means[matches[:, 0], :2], source.means[matches[:, 1], :2]
    cov_t, cov_s = target.covs[matches[:, 0], :2, :2], source.covs[matches[:, 1], :2, :2]
    gate2 = float(chi2.ppf(p_conf, 2))
    rng = np.random.default_rng(config.seed)
    a = rng.integers(n_m, size=config.ransac_iterations)
    b = (a + rng.integers(1, n_m, size=config.ransac_iterations)) % n_m
    # a rigid motion keeps distances: the separation of two pairs must agree within its own σ
    u_s, u_d = src[a] - src[b], dst[a] - dst[b]
    len_s, len_d = np.linalg.norm(u_s, axis=1), np.linalg.norm(u_d, axis=1)
    e_s, e_d = u_s / np.maximum(len_s, 1e-12)[:, None], u_d / np.maximum(len_d, 1e-12)[:, None]
    var = (np.einsum("hi,hij,hj->h", e_s, cov_s[a] + cov_s[b], e_s)
           + np.einsum("hi,hij,hj->h", e_d, cov_t[a] + cov_t[b], e_d))
    valid = (len_s > 1e-9) & ((len_s - len_d) ** 2 <= chi2.ppf(p_conf, 1) * var)
    if not valid.any():
        return refuse(f"no two of {n_m} matches keep their separation within its χ²₁({p_conf}) gate")
    pick = np.stack([a, b], 1)[valid]
    hyp = rigid_transform_2d(src[pick], dst[pick])  # (H, 3)
    # each hypothesis's own covariance from its two pairs, (Σ JᵀS⁻¹J)⁻¹ (4 equations, 3 unknowns)
    jac_h = transform_jacobian(hyp, src[pick])  # (H, 2, 2, 3)
    s_h = residual_covariances(hyp[:, 2], cov_t, cov_s)  # (H, P, 2, 2)
    s_pick = np.take_along_axis(s_h, pick[:, :, None, None], axis=1)
    info_h = np.einsum("hnki,hnkl,hnlj->hij", jac_h, np.linalg.inv(s_pick), jac_h)
    ok = np.linalg.cond(info_h) < 1e12
    hyp, s_h, pick = hyp[ok], s_h[ok], pick[ok]
    if not len(hyp):
        return refuse(f"no two of {n_m} matches fix a transform")
    c_h = np.linalg.inv(info_h[ok])
    jac_all = transform_jacobian(hyp, np.broadcast_to(src, (len(hyp),) + src.shape))  # (H, P, 2, 3)
    pred = s_h + jac_all @ c_h[:, None] @ np.swapaxes(jac_all, -1, -2)
    res_h = apply_transform(hyp, src[None]) - dst[None]  # (H, P, 2)
    # a wrong match lands anywhere on the target map: density 1 / its extent
    ext = np.ptp(target.means[:, :2], axis=0) if len(target) > 1 else np.zeros(2)
    s0 = residual_covariances(0.0, cov_t, cov_s)
    area = max(float(ext[0] * ext[1]), float((np.pi * gate2 * np.sqrt(np.maximum(np.linalg.det(s0), 0.0))).max()))
    # each hypothesis with each unmodelled variance of the grid; the most likely pair
    loglik = np.stack([contaminated_loglik(res_h, pred + v * np.eye(2), area)[0] for v in UNMODELLED_GRID])  # (G, H)
    g_best, h_best = np.unravel_index(int(np.argmax(loglik)), loglik.shape)
    best, cov_fit, u2 = hyp[h_best], c_h[h_best], float(UNMODELLED_GRID[g_best])

    def gated(t: np.ndarray, c: np.ndarray, v: float) -> np.ndarray:
        """Matches within χ²₂(p) of t with both landmarks' covariance, the unmodelled variance v
        [m²] and the transform's covariance."""
        jac = transform_jacobian(t, src)
        cov = residual_covariances(t[2], cov_t, cov_s) + v * np.eye(2) + jac @ c @ jac.transpose(0, 2, 1)
        return np.flatnonzero(mahalanobis2(apply_transform(t, src) - dst, cov) <= gate2)

    inl = gated(best, cov_fit, u2)
    for _ in range(10):
        if inl.size < 2:
            break
        best, cov_fit = gls_refine(best, src[inl], dst[inl], cov_s[inl], cov_t[inl] + u2 * np.eye(2))
        u2_new = unmodelled_variance(apply_transform(best, src) - dst, residual_covariances(best[2], cov_t, cov_s), area)
        new = gated(best, cov_fit, u2_new)
        done = np.array_equal(new, inl) and abs(u2_new - u2) <= 1e-3 * max(u2, 1e-12)
        inl, u2 = new, u2_new
        if done:
            break
    cov_t = cov_t + u2 * np.eye(2)
    n = int(inl.size)
    if n < 2:
        return refuse(f"no two of {n_m} matches agree within their χ²₂({p_conf}) gates", best, inl)
    best, cov_fit = gls_refine(best, src[inl], dst[inl], cov_s[inl], cov_t[inl])
    s_in = residual_covariances(best[2], cov_t[inl], cov_s[inl])
    x2 = float(mahalanobis2(apply_transform(best, src[inl]) - dst[inl], s_in).sum())
    dof = 2 * n - 3
    # chance: each further match inside its gate ellipse, out of the target map's extent
    s_all = residual_covariances(best[2], cov_t, cov_s)
    ellipse = np.pi * gate2 * np.sqrt(np.maximum(np.linalg.det(s_all), 0.0))
    area = max(area, float(ellipse.max()))
    q = float(np.clip(ellipse / area, 0.0, 1.0).mean())
    chance = float(min(1.0, comb(n_m, 2) * binom.sf(n - 3, n_m - 2, q)))
    reason = ""
    if n < 3:
        reason = f"{n} of {n_m} matches in their χ²₂({p_conf}) gates: two fix any transform, a third is needed to test it"
    elif not x2 <= chi2.ppf(p_conf, dof):
        reason = f"inlier residuals χ² {x2:.1f} > χ²_{dof}({p_conf}) {chi2.ppf(p_conf, dof):.1f}: the maps disagree"
    elif not chance <= 1 - p_conf:
        reason = (f"{n} of {n_m} matches agree, which a wrong transform would give with probability {chance:.3f} "
                  f"(gate {q:.3f} of the map's extent): explainable by chance")
    cov = cov_fit * max(1.0, x2 / dof) if dof > 0 else cov_fit
    rmse = float(np.sqrt(np.mean(((apply_transform(best, src[inl]) - dst[inl]) ** 2).sum(1))))
    return GatedAlignment(best, cov, matches, inl, x2, dof, chance, reason == "", reason, rmse, float(np.sqrt(u2)))


def pose_jacobian_transform(transform: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(3, 3) Jacobian of T ⊕ x (x a local pose (3,)) with respect to T = (tx, ty, θ)."""
    jt = np.eye(3)
    jt[:2] = transform_jacobian(transform, np.asarray(x, float)[None, :2])[0]
    return jt


def reference_spread(central: MultiRobotFastSLAM, local: MultiRobotFastSLAM, k: int, transform: np.ndarray) -> np.ndarray:
    """P_ref (3, 3): robot k of ``local``'s pose covariance (particles plus undrawn motion noise)
    rotated into the common frame by ``transform``, plus the mean pose covariance of the robots of
    ``central`` (the spread with which the common filter holds its frame)."""
    c, s = np.cos(transform[2]), np.sin(transform[2])
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    own = rot @ local.estimate().cov[k] @ rot.T
    return own + central.estimate().cov.mean(0)


def absorbable(pose_cov: np.ndarray, reference: np.ndarray) -> float:
    """tr(P_ref⁻¹ P_T): E[eᵀP_ref⁻¹e] of the transform's pose error e ~ N(0, P_T) seen from the
    joined cloud (absorbable when ≤ 3). Pseudo-inverse for a degenerate reference."""
    return float(np.trace(np.linalg.pinv(reference, hermitian=True) @ pose_cov))


@dataclass(frozen=True)
class Evidence:
    """One piece of evidence for a robot's local → common transform.

    Attributes:
        transform: (3,) local → common (tx [m], ty [m], θ [rad]); cov: (3, 3).
        kind: what it is, for the log.
        strong: may join alone (an alignment passing the absorbability test).
        source: "alignment" or "sighting". Two alignments of the same robot never confirm each
            other: they are fitted to largely the same landmarks of the same two maps, so they
            agree whether or not they are right (a weak one waits until it is strong alone or a
            sighting agrees); two sightings do (separate readings; what they catch is a misread
            barcode or range, not a bias both share).
    """

    transform: np.ndarray
    cov: np.ndarray
    kind: str
    strong: bool = False
    source: str = "alignment"


def evidence_distance(a: Evidence, b: Evidence) -> float:
    """(T_b − T_a)ᵀ(Cov T_a + Cov T_b)⁻¹(T_b − T_a), θ wrapped: χ²(3) for two independent
    estimates of the same transform."""
    d = np.asarray(b.transform, float) - np.asarray(a.transform, float)
    d[2] = wrap_angle(d[2])
    return float(d @ np.linalg.solve(a.cov + b.cov, d))


@dataclass
class JoinGate:
    """Evidence for robots not joined yet, held until it suffices (test 3 of the module).

    Attributes:
        window: seconds over which a held piece can confirm a new one (None: every piece that
            passes its own tests is trusted alone).
        threshold: χ²₃ quantile of two agreeing pieces.
        held: robot -> [(time [s], Evidence)] within the window.
        log: robot -> why a piece did not lead to a join.
    """

    window: float | None
    threshold: float
    held: dict[str, list[tuple[float, Evidence]]] = field(default_factory=dict)
    log: dict[str, list[str]] = field(default_factory=dict)

    @classmethod
    def from_config(cls, config: FusionConfig) -> JoinGate:
        return cls(config.evidence_window, float(chi2.ppf(config.join_confidence, 3)))

    def offer(self, robot: str, time_s: float, ev: Evidence) -> Evidence | None:
        """A new piece of evidence for ``robot`` at ``time_s`` [s].

        Returns:
            ``ev`` when the robot may join with it (it agrees with a held independent piece, or
            it is strong and nothing held contradicts it; without a window, a sighting or a strong
            alignment alone), else None (``ev`` held, the reason appended to ``log``). The
            confirming piece is used as it is, not averaged: two sightings 0.2 s apart share most
            of their error.
        """
        if self.window is None:
            if ev.strong or ev.source == "sighting":
                return ev
            self.log.setdefault(robot, []).append(f"{time_s:.1f} s: {ev.kind}: weak evidence, not joined")
            return None
        held = [h for h in self.held.get(robot, []) if time_s - h[0] <= self.window]
        dist = [evidence_distance(h[1], ev) for h in held
                if not (h[1].source == ev.source == "alignment")]
        if (dist and min(dist) <= self.threshold) or (not dist and ev.strong):
            self.held.pop(robot, None)
            return ev
        if dist:
            self.log.setdefault(robot, []).append(
                f"{time_s:.1f} s: {ev.kind} disagrees with held evidence (distance² {min(dist):.1f} > "
                f"{self.threshold:.1f}): held, not joined")
        else:
            self.log.setdefault(robot, []).append(
                f"{time_s:.1f} s: {ev.kind} held until a second piece of evidence within {self.window:.0f} s agrees")
        # a newer alignment replaces older ones (same maps, more landmarks)
        keep = [h for h in held if not (h[1].source == ev.source == "alignment")]
        self.held[robot] = [*keep, (time_s, ev)]
        return None
