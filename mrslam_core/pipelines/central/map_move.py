"""A robot's pose checked against the older map: lost or not, decided in every particle by Bayes.

The correction of the central mapper (:class:`~.corrections.Corrections`) asks, for one robot,
whether the map contradicts its pose, and answers through probabilities, not thresholds:

- The evidence is the robot's recent stereo points ``frame`` (base_link at its current pose) and
  the older landmarks of each particle. Each point may be any landmark of a similar descriptor
  (its candidates, up to ``k`` nearest within the descriptor gate), or none of them (a new
  landmark, an occluded one, a look-alike): per point and particle
  p(f | x) = (1 − η)·(1/n) Σ_candidates N(R(x)f + t(x) − μ; 0, C) + η/A, with
  C = Σ_landmark + R Σ_point Rᵀ + σ_floor² I (planar), n its number of candidates and A the area
  the older map was searched over. Summing over candidates instead of taking the best match keeps
  a pose that explains a point by its true landmark as likely as one that explains it by a
  look-alike.
- The pose prior is a contaminated normal: with probability 1 − ε the robot is where its filter
  says, N(x; x_m, P) with P the spread of its particles; with probability ε it is lost (wheels
  slipped during a blind turn, a gap in its data), uniformly within ``max_shift`` of x_m and
  ``max_turn`` of its heading.
- The two hypotheses' evidences are integrals of the likelihood under each prior; aligning the
  frame to the older map (RANSAC over descriptor matches) gives the pose T, Σ_T where the
  likelihood peaks if the robot is lost, refitting it near the filter's estimate gives the peak
  if it is not (:func:`refine`), and Laplace's method evaluates both integrals at those modes
  (:func:`lost_or_not`). In each particle the robot is found lost with its posterior
  probability, and a lost robot's pose is drawn at its best mode.

The particle weights are left as they are: the frame's points were weighed by the filter when
they came; the decision only chooses, per particle, which hypothesis its pose follows.

A robot the map agrees with stays where it is; one the older map places elsewhere is moved when
the evidence outweighs the prior odds ε/(1 − ε): the fit must be improbable under the filter's
spread P and explain the frame at least as well as the filter's pose.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from mrslam_core.geometry.se2 import wrap_angle
from mrslam_core.pipelines.central.map_move_kernels import frame_log_likelihood_kernel
from mrslam_core.slam.models import LOG_2PI


@dataclass(frozen=True)
class MoveResult:
    """The decision for one robot in every particle.

    Attributes:
        poses: (M, 3) the robot's poses afterwards (map frame).
        lost: (M,) bool, particles in which the robot was found lost and moved.
        p_lost: (M,) the posterior probability of "lost".
        log_e0: (M,) log evidence of "where the filter says"; log_e1 (M,) of "lost".
    """

    poses: np.ndarray
    lost: np.ndarray
    p_lost: np.ndarray
    log_e0: np.ndarray
    log_e1: np.ndarray


def candidate_pairs(world_desc: np.ndarray, frame_desc: np.ndarray, max_sq_dist: float, k: int) -> np.ndarray:
    """(P, 2) int64 (world row, frame row): each frame point's ``k`` nearest world descriptors within
    squared distance ``max_sq_dist`` (000 eq. 16), sorted by frame row."""
    if len(world_desc) == 0 or len(frame_desc) == 0:
        return np.zeros((0, 2), np.int64)
    k = min(k, len(world_desc))
    d, i = cKDTree(np.asarray(world_desc, float)).query(
        np.asarray(frame_desc, float), k=k, distance_upper_bound=np.sqrt(max_sq_dist) + 1e-9)
    d, i = d.reshape(len(frame_desc), k), i.reshape(len(frame_desc), k)
    src, col = np.nonzero(np.isfinite(d))
    return np.column_stack([i[src, col], src]).astype(np.int64)


def frame_log_likelihood(
    poses: np.ndarray, points: np.ndarray, point_covs: np.ndarray, pairs: np.ndarray,
    lm_mean: np.ndarray, lm_cov: np.ndarray, held: np.ndarray, outlier_probability: float,
    log_area: float, floor: float,
) -> np.ndarray:
    """log p(frame | pose) for S poses in each particle (M, S), up to the constant of the points
    without candidates (the same for every pose).

    Args:
        poses: (M, S, 3) robot poses (map frame) [m, m, rad].
        points: (N, ≥2) frame points in the robot's base_link [m]; point_covs (N, ≥2, ≥2).
        pairs: (P, 2) (world row, frame row) candidate pairs, sorted by frame row; lm_mean
            (M, P, ≥2), lm_cov (M, P, ≥2, ≥2): the pairs' landmarks in each particle; held (M, P):
            whether the particle holds that landmark.
        outlier_probability: η, the chance a point has no counterpart among its candidates.
        log_area: log A [m²], A the area a point without counterpart may lie in.
        floor: σ [m] added per axis to every residual's covariance (the frame's own chaining error).
    """
    m, n_pose = poses.shape[:2]
    if pairs.size == 0:
        return np.zeros((m, n_pose))
    rows = pairs[:, 1]
    starts = np.flatnonzero(np.r_[True, rows[1:] != rows[:-1]])
    count = np.diff(np.r_[starts, rows.size])
    cov = point_covs[rows]

    def col(x: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(x, dtype=float)

    return frame_log_likelihood_kernel(
        col(poses[..., :3]), col(points[rows, 0]), col(points[rows, 1]), col(cov[:, 0, 0]), col(cov[:, 0, 1]),
        col(cov[:, 1, 1]), col(lm_mean[..., 0]), col(lm_mean[..., 1]), col(lm_cov[..., 0, 0]),
        col(lm_cov[..., 0, 1]), col(lm_cov[..., 1, 1]), np.ascontiguousarray(held, dtype=np.bool_),
        starts.astype(np.int64), count.astype(np.int64), np.log1p(-outlier_probability) - np.log(count),
        float(np.log(outlier_probability) - log_area), float(floor) ** 2)


def warm_up() -> float:
    """Load the compiled frame likelihood (numba: from its cache, or compiled once per machine,
    0.4-5 s) now instead of inside the first map check, where it would hold a live node while its
    input queues fill. Returns the wall time it took [s]."""
    t0 = time.perf_counter()
    frame_log_likelihood(np.zeros((1, 1, 3)), np.ones((1, 3)), np.eye(3)[None] * 1e-3, np.zeros((1, 2), np.int64),
                         np.zeros((1, 1, 3)), np.eye(3)[None, None] * 1e-3, np.ones((1, 1), bool), 0.5, 0.0, 0.03)
    return time.perf_counter() - t0


def _log_normal(x: np.ndarray, mean: np.ndarray, inv: np.ndarray, logdet: float) -> np.ndarray:
    d = x - mean
    d[..., 2] = wrap_angle(d[..., 2])
    return -0.5 * (np.einsum("...i,ij,...j->...", d, inv, d) + logdet + 3 * LOG_2PI)


def refine(pose: np.ndarray, frame_xy: np.ndarray, world_xy: np.ndarray, pairs: np.ndarray, distance: float,
           rounds: int = 3) -> np.ndarray | None:
    """The frame's best fit near ``pose`` (3,): each frame point (N, 2, base_link) paired with
    its nearest candidate landmark (``pairs`` (P, 2) (world row, frame row) into world_xy (W, 2),
    map frame) within ``distance`` [m] of where ``pose`` puts it, and the rigid motion refitted
    to those pairs, ``rounds`` times; None with fewer than three pairs. The local mode of the
    frame's likelihood when the robot is where its filter says, which its particles, a
    centimetre or two apart, miss by many nats (the caller keeps it only within that
    hypothesis's prior: along a repetitive wall the refit can slide to a look-alike)."""
    from mrslam_core.fusion.alignment import apply_transform, rigid_transform_2d

    for _ in range(rounds):
        moved = apply_transform(pose, frame_xy[pairs[:, 1]])
        dist = np.linalg.norm(moved - world_xy[pairs[:, 0]], axis=1)
        order = np.lexsort((dist, pairs[:, 1]))
        first = order[np.r_[True, pairs[order[1:], 1] != pairs[order[:-1], 1]]]  # nearest per point
        use = first[dist[first] <= distance]
        if use.size < 3:
            return None
        pose = rigid_transform_2d(frame_xy[pairs[use, 1]], world_xy[pairs[use, 0]])
    return pose


def lost_or_not(
    poses: np.ndarray, spread: np.ndarray, fit: np.ndarray, fit_cov: np.ndarray,
    log_lik, lost_probability: float, max_shift: float, max_turn: float, rng: np.random.Generator,
    local: np.ndarray | None = None,
) -> MoveResult:
    """Decide in every particle whether the robot is where its filter says or lost, and draw a
    lost robot's pose from where the frame fits best (see the module).

    The frame's likelihood L_m of particle m is sharply peaked (tens of points, each a few cm):
    its evidence integrals are taken by Laplace's method at the best of its candidate modes
    (the particle's pose x_m, the frame's fit near the filter's estimate ``local``, and the
    alignment T), with the alignment's covariance Σ_T as every peak's (so the peak volumes
    cancel):
    - "where the filter says": E0 = ∫ L_m(x) N(x; x_m, P) dx ≈ max_j L_m(μ_j) N(μ_j − x_m; 0, P + Σ_T);
    - "lost": E1 = ∫ L_m(x) U(x) dx ≈ U · max_j L_m(μ_j) over the modes within the support of U
      (``max_shift`` and ``max_turn`` of x_m);
    - the robot is lost with the posterior probability ε E1 / (ε E1 + (1 − ε) E0). A lost robot
      takes a pose drawn from N(μ, Σ_T) at its best mode μ, unless that is its own pose (then
      it stays, as it does when not lost: the filter's own update is the posterior there).

    Args:
        poses: (M, 3) the robot's poses (map frame) x_m.
        spread: (3, 3) P.
        fit: (3,) T; fit_cov (3, 3) Σ_T.
        log_lik: callable (M, S, 3) poses -> (M, S) log p(frame | pose) in each particle.
        lost_probability: ε.
        max_shift, max_turn: the support of U [m], [rad].
        rng: the filter's generator (runs stay reproducible).
        local: (3,) the frame's fit near the estimate (:func:`refine`), or None.
    """
    m = poses.shape[0]
    log_u = -np.log(np.pi * max_shift**2 * 2 * max_turn)
    shared = [fit] if local is None else [local, fit]
    modes = np.concatenate([poses[:, None], np.broadcast_to(np.array(shared), (m, len(shared), 3))], axis=1)
    ll = log_lik(modes)  # (M, J)
    cov = spread + fit_cov
    inv, logdet = np.linalg.inv(cov), float(np.linalg.slogdet(cov)[1])
    log_prior = _log_normal(modes, poses[:, None], inv, logdet)
    d = modes - poses[:, None]
    inside = (np.hypot(d[..., 0], d[..., 1]) <= max_shift) & (np.abs(wrap_angle(d[..., 2])) <= max_turn)
    log_e0 = np.max(ll + log_prior, axis=1)
    ll_inside = np.where(inside, ll, -np.inf)
    log_e1 = log_u + ll_inside.max(axis=1)
    log_lost = np.log(lost_probability) + log_e1
    p_lost = np.exp(log_lost - np.logaddexp(log_lost, np.log1p(-lost_probability) + log_e0))
    best = np.argmax(ll_inside, axis=1)
    move = (rng.random(m) < p_lost) & (best > 0)
    out = poses.copy()
    if move.any():
        draw = modes[move, best[move]] + rng.standard_normal((int(move.sum()), 3)) @ np.linalg.cholesky(fit_cov).T
        draw[:, 2] = wrap_angle(draw[:, 2])
        out[move] = draw
    return MoveResult(out, move, p_lost, log_e0, log_e1)
