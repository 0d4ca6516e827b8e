"""Bringing a robot with its own local filter into the central filter (004 section 5).

A robot whose start pose is unknown runs a local :class:`MultiRobotFastSLAM` with K = 1 from its own
origin. Once its map aligns with the central map (transform T, local frame → common frame, and the
inlier landmark pairs) and the alignment is accepted (:mod:`~mrslam_core.fusion.acceptance`: χ²
consistency, the chance test, absorbability, the evidence gate), the robot joins particle by
particle (:func:`join_filters`):

- every central particle stays as it is (poses, map, weight); each is paired with a local particle
  drawn by the local weights (systematic), so the pairs sample w_c·w_l;
- the pair's transform: T, T refitted by least squares on the pair's own copies of the matched
  landmarks (``per_pair``), T drawn from N(T, Cov T), or a rendezvous anchored per particle;
- the newcomer's pose: the local particle's pose moved by that transform (its drift and pending
  motion covariances moved into the common frame, widened by Cov T);
- landmarks: a matched landmark keeps the common map's copy (T was fitted to it; fusing the local
  copy would count it twice and let the newcomer move the common map); a central particle that
  lacks it gets the local copy, moved; the local particle's other landmarks are moved and added;
- weight: unchanged, or (``pair_likelihood``) times the tempered likelihood of the pair's matched
  landmarks agreeing.

So a join leaves every robot and landmark already in the central filter as it was. From then on
the robot is one more robot of the joint filter. A robot that restarts (a new local filter for a
name already in the central filter) goes through the same path; its pose column is replaced.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from mrslam_core.fusion.acceptance import (
    Evidence,
    GatedAlignment,
    JoinGate,
    absorbable,
    chi2_align,
    pose_jacobian_transform,
    reference_spread,
    residual_covariances,
    with_marginals,
)
from mrslam_core.fusion.alignment import apply_transform, match_descriptors, transform_jacobian
from mrslam_core.fusion.config import FusionConfig
from mrslam_core.fusion.maps import FusionError, LandmarkMap
from mrslam_core.geometry.se2 import compose
from mrslam_core.linalg import quad_form, sym_inv_det
from mrslam_core.slam.filter import MultiRobotFastSLAM
from mrslam_core.slam.resampling import normalise_log_weights

LOG_2PI = float(np.log(2.0 * np.pi))


@dataclass(frozen=True)
class JoinResult:
    """What joining a local filter into the central one did.

    Attributes:
        robot: name of the joined robot in the central filter.
        transform: (3,) local frame → common frame (tx [m], ty [m], θ [rad]).
        fused: matched landmarks (slot pairs) fused.
        added: local landmarks added to the central map as new landmarks.
        dropped: local landmarks left out (outlier matches with ``source_outliers = drop``).
        ancestors: (M, 2) (central particle, local particle) behind each joined particle.
        slot_map: (S_local,) central slot of each local slot (-1: not carried over).
        transforms: (M, 3) the transform each joined particle used (``transform`` unless
            refitted per pair or sampled).
    """

    robot: str
    transform: np.ndarray
    fused: int
    added: int
    dropped: int
    ancestors: np.ndarray
    slot_map: np.ndarray
    transforms: np.ndarray


def move_landmarks(
    transform: np.ndarray, mean: np.ndarray, cov: np.ndarray, transform_cov: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Landmarks moved by planar transforms (tx, ty, θ): p' = R·p + t, Σ' = R·Σ·Rᵀ (z and its
    variance unchanged), plus (``transform_cov``, the
    (3, 3) covariance of the transform) J_T·Cov T·J_Tᵀ on x, y with J_T = [I₂ | ∂R/∂θ·p] at
    each landmark's position p before the move.

    Args:
        transform: (3,) one transform, or (M, 3) one per leading row of ``mean``.
        mean: (M, P, dim) or (P, dim), dim 2 or 3 [m]; cov: (..., dim, dim) [m²].
    """
    dim = mean.shape[-1]
    t = np.asarray(transform, float)
    c, s = np.cos(t[..., 2]), np.sin(t[..., 2])
    r = np.broadcast_to(np.eye(dim), t.shape[:-1] + (dim, dim)).copy()
    r[..., 0, 0], r[..., 0, 1], r[..., 1, 0], r[..., 1, 1] = c, -s, s, c
    off = np.zeros(t.shape[:-1] + (dim,))
    off[..., :2] = t[..., :2]
    if t.ndim == 2:  # one transform per particle row: broadcast over the P landmarks
        r, off = r[:, None], off[:, None]
    moved = (r @ mean[..., None])[..., 0] + off
    out = r @ cov @ np.swapaxes(r, -1, -2)
    if transform_cov is not None:
        jac = transform_jacobian(t, mean[..., :2])
        out[..., :2, :2] += jac @ transform_cov @ np.swapaxes(jac, -1, -2)
    return moved, out


def pose_transform_cov(local: MultiRobotFastSLAM, k: int, transform: np.ndarray, transform_cov: np.ndarray) -> np.ndarray:
    """J_T·Cov T·J_Tᵀ (3, 3): the covariance the transform's own uncertainty gives the pose
    T ⊕ x of robot k of ``local``, at its weighted mean local position x (map frame)."""
    w = np.exp(local.log_w)
    x = w @ local.poses[:, k, :2]
    jt = np.eye(3)
    jt[:2] = transform_jacobian(transform, x[None])[0]
    return jt @ transform_cov @ jt.T


def _moved_pose_covariances(
    local: MultiRobotFastSLAM, k: int, transform: np.ndarray, transform_cov: np.ndarray | None,
    to_pending: bool = False,
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The local robot's drift and pending motion covariances (3, 3) moved into the common frame:
    J_x C J_xᵀ for the pose x ↦ T ⊕ x, plus J_T Cov(T) J_Tᵀ on the drift (the alignment's own
    uncertainty, at the local weighted mean pose) and, ``to_pending``, on the pending motion
    covariance too. None where the local filter holds none."""
    drift = getattr(local, "drift_cov", {}).get(k)
    pending = getattr(local, "pending_cov", {}).get(k)
    c, s = np.cos(transform[2]), np.sin(transform[2])
    jx = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    if drift is not None:
        drift = jx @ drift @ jx.T
    if pending is not None:
        pending = jx @ pending @ jx.T
    if transform_cov is not None and np.isfinite(transform_cov).all():
        from_t = pose_transform_cov(local, k, transform, transform_cov)
        drift = from_t if drift is None else drift + from_t
        if to_pending:
            pending = from_t if pending is None else pending + from_t
    return drift, pending


def systematic_draw(log_w: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` indices drawn from normalised log weights (P,) by systematic (low-variance)
    resampling, sorted (n may differ from P: here M of the M × L pairs)."""
    cdf = np.cumsum(np.exp(log_w))
    cdf[-1] = 1.0
    u = (rng.random() + np.arange(n)) / n
    return np.searchsorted(cdf, u, side="right").clip(0, log_w.size - 1)


def gls_pair_transforms(
    transform: np.ndarray, src: np.ndarray, dst: np.ndarray, cov_src: np.ndarray, cov_dst: np.ndarray, w: np.ndarray,
    iterations: int = 3,
) -> np.ndarray:
    """Each row's transform refitted by generalised least squares of dst ≈ R·src + t over its
    pairs, each residual with its covariance Σ_dst + R·Σ_src·Rᵀ (Gauss–Newton from ``transform``).
    A stereo landmark is far less certain in depth than across (σ grows with the square of the
    range), so an unweighted fit reads the depth errors of a few far landmarks as a turn.

    Args:
        transform: (M, 3) start (tx [m], ty [m], θ [rad]), source frame → target frame.
        src, dst: (M, P, 2) [m] the pairs' planar positions in the source and target frames.
        cov_src, cov_dst: (M, P, 2, 2) [m²] their covariances.
        w: (M, P) 1 for a pair the row holds, 0 for one it lacks (each row needs two).

    Returns:
        (M, 3) the fitted transforms.
    """
    t = np.array(transform, float)
    for _ in range(iterations):
        cov = residual_covariances(t[:, 2], cov_dst, cov_src) + 1e-12 * np.eye(2)  # (M, P, 2, 2)
        inv = np.linalg.inv(cov) * w[..., None, None]
        jac = transform_jacobian(t, src)  # (M, P, 2, 3)
        res = apply_transform(t, src) - dst
        info = np.einsum("mpki,mpkl,mplj->mij", jac, inv, jac)
        grad = np.einsum("mpki,mpkl,mpl->mi", jac, inv, res)
        step = np.linalg.solve(info + 1e-12 * np.eye(3), -grad[..., None])[..., 0]
        t += step
        if np.abs(step).max() < 1e-10:
            break
    return t


def join_filters(
    central: MultiRobotFastSLAM,
    local: MultiRobotFastSLAM,
    transform: np.ndarray,
    pairs: np.ndarray,
    config: FusionConfig,
    robot: str | None = None,
    drop: np.ndarray | None = None,
    transform_cov: np.ndarray | None = None,
    per_pair: bool = False,
    pose_cov: np.ndarray | None = None,
    pair_transforms: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
) -> JoinResult:
    """Join ``local`` (K = 1) into ``central`` particle by particle (004 section 5).

    Args:
        central: the common filter (M particles); modified in place.
        local: the robot's own filter in its own frame; read only.
        transform: (3,) local frame → central map frame.
        pairs: (P, 2) (central slot, local slot) of landmarks known to be the same (the
            alignment's inliers).
        config: ``pair_likelihood``, ``pair_likelihood_temper``.
        robot: the robot's name in the central filter (default: the local filter's robot).
        drop: local slots not to carry over.
        transform_cov: (3, 3) covariance of ``transform``; when given, each joined particle
            draws its own transform from N(transform, transform_cov) and moves its local
            ancestor's pose and landmarks with it, so the joint filter can weigh alignments
            (a single transform for all particles makes the merged robot overconfident).
        per_pair: refit the transform for each drawn (central, local) pair by least squares on
            the matched landmarks both particles hold (at least two; else ``transform``), so
            that the robot is placed consistently with each central particle's own map.
        pose_cov: (3, 3) covariance of ``transform`` added (propagated to the robot's pose) to
            the drift covariance it enters the joint filter with (default ``transform_cov``); the
            local filter's drift and pending motion noise are moved into the common frame too.
            With ``config.transform_uncertainty = "proposal"`` and no per-particle sampling
            (``transform_cov`` None) it is also added to the robot's pending motion covariance
            and, at each landmark's position, to the moved local landmarks' covariances.
        pair_transforms: ``f(anc_c (M,), anc_l (M,)) -> (M, 3)``: each drawn pair's own
            transform from its central and local ancestors (a rendezvous anchored per particle,
            :func:`mrslam_core.fusion.rendezvous.anchored_transforms`); replaces the refit and
            the sampling from ``transform_cov``, and counts as sampled (nothing goes into the
            proposal or the landmarks' covariances on top).

    In the per-pair refit, a pair whose own matched landmarks lie within
    ``config.min_pair_spread`` (default ``min_spread``) of their centroid keeps ``transform``.
    """
    t = np.asarray(transform, float)
    if t.shape != (3,) or not np.isfinite(t).all():
        raise FusionError(f"transform must be finite (3,), got {transform}")
    cs_store, ls_store = central.landmarks, local.landmarks
    if cs_store.dim != ls_store.dim:
        raise FusionError(f"landmark dimensions differ: central {cs_store.dim}, local {ls_store.dim}")
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    name = robot or local.robots[0]
    kl = local.index.get(name, 0)
    m = central.num_particles
    cs, ls = pairs[:, 0], pairs[:, 1]

    # every central particle stays as it is (poses, map, weight): the join only adds the newcomer;
    # each is paired with a local particle drawn by its weight, so the pairs sample w_c·w_l
    anc_c = np.arange(m)
    anc_l = systematic_draw(normalise_log_weights(np.asarray(local.log_w, float)), m, central.rng)
    anc_l = anc_l[central.rng.permutation(m)]
    # per particle transform: refitted on the pair's own copies of the matched landmarks
    # (each central particle's map may sit slightly differently), or one for all
    t_all = np.broadcast_to(t, (m, 3)).copy()
    if per_pair and len(pairs) >= 2 and pair_transforms is None:
        mc, sc, ec = cs_store.gather(anc_c[:, None], cs[None], ("mean", "cov", "exists"))
        ml, sl, el = ls_store.gather(anc_l[:, None], ls[None], ("mean", "cov", "exists"))
        w = (ec & el).astype(float)
        n_w = w.sum(1)
        ok = n_w >= 2
        # the pair's own spread of matched landmarks (central copies): a rotation needs it
        cen = (w[..., None] * mc[..., :2]).sum(1) / np.maximum(n_w, 1)[:, None]
        spread = np.sqrt((w * ((mc[..., :2] - cen[:, None]) ** 2).sum(-1)).sum(1) / np.maximum(n_w, 1))
        min_pair_spread = config.min_spread if config.min_pair_spread is None else config.min_pair_spread
        ok &= spread >= min_pair_spread
        if ok.any():
            t_all[ok] = gls_pair_transforms(t_all[ok], ml[ok, :, :2], mc[ok, :, :2], sl[ok, :, :2, :2],
                                            sc[ok, :, :2, :2], w[ok])
    if pair_transforms is not None:
        t_all = np.asarray(pair_transforms(anc_c, anc_l), float).reshape(m, 3)
    elif transform_cov is not None and np.isfinite(transform_cov).all():
        chol = np.linalg.cholesky(0.5 * (transform_cov + transform_cov.T) + 1e-12 * np.eye(3))
        t_all += central.rng.standard_normal((m, 3)) @ chol.T
    # the drawn pairs weighted by how well their matched landmarks agree once moved by their own
    # transform (the "new observation" 004 section 5 resamples on), tempered
    pair_ll = np.zeros(m)
    if config.pair_likelihood and len(pairs):
        mc, sc, ec = cs_store.gather(anc_c[:, None], cs[None], ("mean", "cov", "exists"))
        ml, sl, el = ls_store.gather(anc_l[:, None], ls[None], ("mean", "cov", "exists"))
        ml, sl = move_landmarks(t_all, ml.astype(float), sl.astype(float))
        dim = ml.shape[-1]
        inv, det = sym_inv_det(sc.astype(float) + sl)
        ll = -0.5 * (quad_form(mc - ml, inv) + np.log(det) + dim * LOG_2PI)
        pair_ll = config.pair_likelihood_temper * np.where(ec & el, ll, 0.0).sum(1)
    # particles: central ancestors, then the robot's pose moved into the common frame
    central.score = central.score + local.score[anc_l]
    central.log_w = normalise_log_weights(central.log_w + pair_ll)
    stamp = local.last_stamp.get(local.robots[kl])
    sampled = pair_transforms is not None or (transform_cov is not None and np.isfinite(transform_cov).all())
    to_proposal = config.transform_uncertainty == "proposal" and not sampled and pose_cov is not None
    lm_cov = pose_cov if to_proposal and np.isfinite(pose_cov).all() else None
    drift, pending = _moved_pose_covariances(local, kl, t, transform_cov if pose_cov is None else pose_cov, to_proposal)
    joined = compose(t_all, local.poses[anc_l, kl])
    sigma = np.asarray(config.join_pose_sigma, float)
    if sigma.any():
        joined = joined + central.rng.standard_normal((m, 3)) * sigma
        spread = np.diag(sigma**2)
        drift = spread if drift is None else drift + spread
    central.add_robot(name, joined, stamp, drift, pending)

    slot_map = np.full(ls_store.size, -1, np.int64)
    if len(pairs) and config.carry_landmarks:
        # a matched landmark keeps the common map's copy: the local copy's position in the common
        # frame came through T, which was fitted to the common copies, so fusing it would count
        # that twice and let the newcomer's map move the common one (and the robots on it); only a
        # particle that lacks the landmark gets the local copy, moved
        ec, = cs_store.gather(anc_c[:, None], cs[None], ("exists",))
        ml, sl, el, nl, scl = ls_store.gather(anc_l[:, None], ls[None], ("mean", "cov", "exists", "count", "score"))
        ml, sl = move_landmarks(t_all, ml.astype(float), sl.astype(float), lm_cov)
        wi, wp = np.nonzero(el & ~ec)
        if wi.size:
            cs_store.write(wi, cs[wp], mean=ml[wi, wp], cov=sl[wi, wp], exists=True, count=nl[wi, wp],
                           score=np.minimum(scl[wi, wp], central.config.existence.max_score))
            cs_store.refresh_reference(np.unique(cs[wp]))
        slot_map[ls] = cs

    held = ls_store.exists_dense()[anc_l]  # (M, S_local)
    rest = np.flatnonzero(held.any(axis=0))
    skip = np.zeros(ls_store.size, bool)
    skip[ls] = True
    dropped = 0
    if drop is not None and len(drop):
        drop = np.asarray(drop, np.int64)
        dropped = int(np.isin(rest, drop[~skip[drop]]).sum())
        skip[drop] = True
    rest = rest[~skip[rest]]
    if rest.size and config.carry_landmarks:
        mean, cov, ex, cnt = ls_store.gather(anc_l[:, None], rest[None])
        mean, cov = move_landmarks(t_all, mean.astype(float), cov.astype(float), lm_cov)
        slot_map[rest] = central.insert_landmarks(mean, cov, ex, ls_store.descriptor[rest], cnt)
        cs_store.origin[slot_map[rest]] = ls_store.origin[rest]  # the creating track ids
        cs_store.maker[slot_map[rest]] = central.index[name]
    if not config.carry_landmarks:
        return JoinResult(name, t.copy(), 0, 0, int(rest.size + len(pairs)) + dropped,
                          np.column_stack([anc_c, anc_l]), slot_map, t_all)
    return JoinResult(name, t.copy(), len(pairs), int(rest.size), dropped,
                      np.column_stack([anc_c, anc_l]), slot_map, t_all)


def assess_alignment(
    central: MultiRobotFastSLAM, local: MultiRobotFastSLAM, config: FusionConfig, robot: str | None = None
) -> tuple[GatedAlignment, Evidence | None, LandmarkMap, LandmarkMap]:
    """Align the local filter's map to the central one and judge it (:mod:`~mrslam_core.fusion.acceptance`).

    Descriptor matches between the two best maps; each matched landmark at its marginal over its
    filter's particles; :func:`~mrslam_core.fusion.acceptance.chi2_align`; then the transform's
    covariance propagated to the robot's local pose against the spread the joined cloud carries
    (:func:`~mrslam_core.fusion.acceptance.reference_spread`).

    Returns:
        (the alignment, the evidence it gives — None when inconsistent; ``strong`` when
        absorbable —, the target and source maps with marginals).
    """
    target = LandmarkMap.from_filter(central, z_variance=config.z_variance)
    source = LandmarkMap.from_filter(local, z_variance=config.z_variance)
    matches = match_descriptors(target.descriptors, source.descriptors, config.descriptor_threshold, config.mutual)
    target = with_marginals(central, target, matches[:, 0])
    source = with_marginals(local, source, matches[:, 1])
    al = chi2_align(target, source, config, matches)
    if not al.consistent:
        return al, None, target, source
    kl = local.index.get(robot, 0) if robot else 0
    x_local = local.estimate().mean[kl]
    jt = pose_jacobian_transform(al.transform, x_local)
    p_t = jt @ al.cov @ jt.T
    load = absorbable(p_t, reference_spread(central, local, kl, al.transform))
    strong = load <= 3.0
    reason = "" if strong else (
        f"{al.inliers.size} inliers: the transform's error at the robot is {load:.1f} times the spread "
        f"the joined cloud carries (tr P_ref⁻¹P_T > 3): weak evidence")
    al = replace(al, reason=reason)
    return al, Evidence(al.transform, al.cov, f"alignment ({al.inliers.size} inliers)", strong, "alignment"), target, source


def join_alignment(
    central: MultiRobotFastSLAM, local: MultiRobotFastSLAM, al: GatedAlignment, target: LandmarkMap,
    source: LandmarkMap, config: FusionConfig, robot: str | None = None,
) -> JoinResult:
    """Join ``local`` into ``central`` with an alignment from :func:`assess_alignment`: its
    inlier landmarks matched, its other matches per ``config.source_outliers``, Cov T per
    ``config.transform_uncertainty`` (every joined particle uses T, refitted per pair with
    ``config.per_particle_alignment``)."""
    inl = al.inlier_pairs
    pairs = np.column_stack([target.ids[inl[:, 0]], source.ids[inl[:, 1]]])
    drop = source.ids[al.outlier_pairs[:, 1]] if config.source_outliers == "drop" else None
    return join_filters(central, local, al.transform, pairs, config, robot, drop, None,
                        config.per_particle_alignment, pose_cov=al.cov)


def try_join(
    central: MultiRobotFastSLAM, local: MultiRobotFastSLAM, config: FusionConfig, robot: str | None = None,
    gate: JoinGate | None = None, time_s: float = 0.0,
) -> tuple[GatedAlignment, JoinResult | None]:
    """Align the local filter's map to the central one and join it if the evidence suffices.

    With ``gate`` (one per team, shared with rendezvous sightings) the alignment is offered to it
    at ``time_s`` [s]: a strong one (consistent and absorbable) joins unless held evidence
    contradicts it, a weak one (consistent, not absorbable) is held until a sighting agrees.
    Without ``gate`` the pipeline has no second, independent source of evidence (the stereo
    central mapper: no sightings), so holding a weak alignment could never end in its
    confirmation — later alignments of the same two maps are not independent of it — while the
    local map drifts on: every consistent alignment joins, and a weak one says so in ``reason``.

    Returns:
        (the alignment — its ``reason`` says why nothing was joined, or that a weak one was —,
        the join or None).
    """
    name = robot or local.robots[0]
    al, ev, target, source = assess_alignment(central, local, config, robot)
    if ev is None:
        return al, None
    if gate is not None and gate.offer(name, time_s, ev) is None:
        return replace(al, reason=gate.log[name][-1]), None
    reason = "" if ev.strong or gate is not None else f"joined without independent evidence: {al.reason}"
    return replace(al, reason=reason), join_alignment(central, local, al, target, source, config, robot)
