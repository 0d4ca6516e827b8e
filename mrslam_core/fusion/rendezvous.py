"""Merging a robot by a rendezvous: two robots that measure each other (issue 8).

When robot i (not merged, its own frame) measures robot j (already in the common filter) at range
r and bearing β_ij, and j measures i at bearing β_ji at about the same time, the pose of j in i's
body frame is fully determined without any landmark:

    position (r cos β_ij, r sin β_ij),   heading θ_j − θ_i = β_ij + π − β_ji,

so i's pose in the common frame is x_j ⊕ (that relative pose)⁻¹, and the local frame → common frame
transform is T = x_i,map ⊕ x_i,local⁻¹. The robot is then joined particle by particle as after a map
alignment (:func:`mrslam_core.fusion.join.join_filters`), each joined particle drawing its own
transform from N(T, Cov T) (Cov T from the sightings' noise and j's pose covariance), so the joint
filter's next sightings and landmark observations weigh them. Local landmarks whose barcode /
descriptor matches a common landmark and agree with it after T within the χ²₂ gate of both
covariances and Cov T are matched (the common copy kept), the other matched ones are dropped
(``source_outliers = drop``) or kept, the rest added, as for a map join.

One mutual sighting is weak evidence (:class:`RendezvousGate`, a
:class:`~mrslam_core.fusion.acceptance.JoinGate`): a misread barcode or a wrong range would merge
the robot wrongly. It is held, and the robot joins when a later piece of evidence within
``FusionConfig.evidence_window`` — a second mutual sighting or a map alignment — agrees,
(T₂ − T₁)ᵀ(Cov T₁ + Cov T₂)⁻¹(T₂ − T₁) below the χ²(3) quantile ``join_confidence``; a disagreeing
pair is logged with its distance. A sighting whose two ranges (i's of j, j's of i) disagree beyond
the χ²(1) quantile is refused outright.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.stats import chi2

from mrslam_core.fusion.acceptance import Evidence, JoinGate, mahalanobis2, residual_covariances, with_marginals
from mrslam_core.fusion.alignment import apply_transform, match_descriptors, transform_jacobian
from mrslam_core.fusion.config import FusionConfig
from mrslam_core.fusion.join import JoinResult, join_filters
from mrslam_core.fusion.maps import LandmarkMap
from mrslam_core.geometry.se2 import compose, inverse, pose_moments, wrap_angle
from mrslam_core.slam.filter import MultiRobotFastSLAM


@dataclass(frozen=True)
class Rendezvous:
    """A mutual sighting and what it implies.

    Attributes:
        relative: (3,) pose of the seen robot j in the seeing robot i's body frame (x [m], y [m], θ [rad]).
        relative_cov: (3, 3) its covariance.
        transform: (3,) local frame of i → common frame.
        transform_cov: (3, 3) its covariance (sightings plus j's pose covariance).
        range_nis: (r_ij − r_ji)² / (var r_ij + var r_ji), the two robots' ranges against each
            other (χ²(1) for correct readings; 0 when not known).
        seen: name of the seen robot j in the common filter ("" when not known).
    """

    relative: np.ndarray
    relative_cov: np.ndarray
    transform: np.ndarray
    transform_cov: np.ndarray
    range_nis: float = 0.0
    seen: str = ""

    def evidence(self) -> Evidence:
        """This sighting as evidence for a join (weak: held until another piece agrees)."""
        return Evidence(self.transform, self.transform_cov, f"sighting with {self.seen}", False, "sighting")


def relative_pose(z_ij: np.ndarray, z_ji: np.ndarray, cov_ij: np.ndarray, cov_ji: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pose of j in i's body frame from i's measurement of j (range [m], bearing [rad]) and j's of i.

    The range is the inverse-variance mean of both ranges; the heading is β_ij + π − β_ji.

    Returns:
        ((3,) relative pose, (3, 3) covariance by first-order propagation).
    """
    z_ij, z_ji = np.asarray(z_ij, float), np.asarray(z_ji, float)
    vi, vj = cov_ij[0, 0], cov_ji[0, 0]
    r = (z_ij[0] / vi + z_ji[0] / vj) / (1 / vi + 1 / vj)
    var_r = 1.0 / (1 / vi + 1 / vj)
    b = z_ij[1]
    rel = np.array([r * np.cos(b), r * np.sin(b), wrap_angle(b + np.pi - z_ji[1])])
    # inputs (r, β_ij, β_ji) -> (x, y, θ)
    jac = np.array([[np.cos(b), -r * np.sin(b), 0.0], [np.sin(b), r * np.cos(b), 0.0], [0.0, 1.0, -1.0]])
    cov_in = np.diag([var_r, cov_ij[1, 1], cov_ji[1, 1]])
    return rel, jac @ cov_in @ jac.T


def rendezvous_transform(
    x_j: np.ndarray, cov_j: np.ndarray, x_i_local: np.ndarray, rel: np.ndarray, rel_cov: np.ndarray
) -> Rendezvous:
    """The local frame → common frame transform of robot i from j's common-frame pose ``x_j`` (3,)
    with covariance ``cov_j``, i's local pose ``x_i_local`` and the relative pose of j in i's frame.

    x_i = x_j ⊕ rel⁻¹ and T = x_i ⊕ x_i,local⁻¹; Cov T by first-order propagation of x_j and rel
    (numerical Jacobians; i's local pose is taken as exact: its own uncertainty stays in its
    local particles).
    """
    def f(v: np.ndarray) -> np.ndarray:
        xi = compose(v[:3], inverse(v[3:]))
        return compose(xi, inverse(x_i_local))

    v0 = np.concatenate([np.asarray(x_j, float), np.asarray(rel, float)])
    t = f(v0)
    jac = np.zeros((3, 6))
    for n in range(6):
        d = np.zeros(6)
        d[n] = 1e-6
        diff = f(v0 + d) - f(v0 - d)
        diff[2] = wrap_angle(diff[2])
        jac[:, n] = diff / 2e-6
    cov_in = np.zeros((6, 6))
    cov_in[:3, :3] = cov_j
    cov_in[3:, 3:] = rel_cov
    return Rendezvous(np.asarray(rel, float), rel_cov, t, jac @ cov_in @ jac.T)


def sighting_transform(
    central: MultiRobotFastSLAM, local: MultiRobotFastSLAM, seen: str,
    z_ij: np.ndarray, z_ji: np.ndarray, cov_ij: np.ndarray, cov_ji: np.ndarray,
) -> Rendezvous:
    """The rendezvous of ``local``'s robot with ``seen`` (a robot of ``central``) now: j's
    weighted mean pose and covariance in ``central``, the local robot's weighted mean pose, the
    two readings ``z_ij`` (its of seen), ``z_ji`` (seen's of it), (range [m], bearing [rad])."""
    est_c, est_l = central.estimate(), local.estimate()
    j = central.index[seen]
    rel, rel_cov = relative_pose(z_ij, z_ji, cov_ij, cov_ji)
    rv = rendezvous_transform(est_c.mean[j], est_c.cov[j], est_l.mean[0], rel, rel_cov)
    nis = float((z_ij[0] - z_ji[0]) ** 2 / (cov_ij[0, 0] + cov_ji[0, 0]))
    return replace(rv, range_nis=nis, seen=seen)


def anchored_transforms(
    x_j: np.ndarray, x_i_local: np.ndarray, rel: np.ndarray, rel_cov: np.ndarray, rng: np.random.Generator,
) -> np.ndarray:
    """Per-particle local → common transforms of a rendezvous, anchored on each particle's own poses.

    For particle m, with j's pose ``x_j[m]`` in its central ancestor, i's local pose
    ``x_i_local[m]`` in its local ancestor and the relative pose drawn from N(rel, rel_cov):
    x_i = x_j[m] ⊕ (rel + ε_m)⁻¹ and T_m = x_i ⊕ x_i_local[m]⁻¹. Every joined particle then puts
    robot i where the sighting places it relative to ITS OWN j (not the weighted mean of j), and
    moves its local map rigidly with its own local pose, so what the local filter does not know
    about its pose relative to its map becomes a spread of the moved landmarks around the robot
    (where it belongs) instead of a spread of the robot around the sighting; the spread of the
    T_m holds j's particle spread, the sightings' noise and the local particles' spread.

    Args:
        x_j, x_i_local: (M, 3) poses; rel: (3,); rel_cov: (3, 3).

    Returns:
        (M, 3) transforms (tx [m], ty [m], θ [rad]).
    """
    x_j, x_i_local = np.asarray(x_j, float), np.asarray(x_i_local, float)
    chol = np.linalg.cholesky(0.5 * (rel_cov + rel_cov.T) + 1e-12 * np.eye(3))
    r = np.asarray(rel, float) + rng.standard_normal((len(x_j), 3)) @ chol.T
    return compose(compose(x_j, inverse(r)), inverse(x_i_local))


def transform_spread(transforms: np.ndarray, log_w: np.ndarray | None = None) -> np.ndarray:
    """Weighted covariance (3, 3) of transforms (M, 3) around their mean (θ by its circular mean,
    deviations wrapped): the Cov T a particle-by-particle join actually realised."""
    t = np.asarray(transforms, float)
    w = np.full(len(t), 1.0 / len(t)) if log_w is None else np.exp(log_w - np.logaddexp.reduce(log_w))
    return pose_moments(t, w)[1]


@dataclass
class RendezvousGate(JoinGate):
    """A :class:`~mrslam_core.fusion.acceptance.JoinGate` that also takes mutual sightings: a
    sighting is weak evidence (held until another piece agrees), refused outright when its two
    ranges (i's of j, j's of i) disagree beyond ``range_threshold`` (χ²₁ quantile: the relative
    pose averages them, which halves one wrong range).

    Attributes:
        range_threshold: largest ``range_nis`` of one sighting.
    """

    range_threshold: float = float("inf")

    @classmethod
    def from_config(cls, config: FusionConfig) -> RendezvousGate:
        p = config.join_confidence
        return cls(config.evidence_window, float(chi2.ppf(p, 3)), range_threshold=float(chi2.ppf(p, 1)))

    def offer_sighting(self, robot: str, time_s: float, rv: Rendezvous) -> Rendezvous | None:
        """A new mutual sighting ``rv`` of ``robot`` with ``rv.seen`` at ``time_s`` [s].

        Returns:
            ``rv`` when held evidence (an earlier sighting, an alignment) agrees with it or no
            window is set; else None (held, or refused; the reason appended to ``log``). The
            sighting is used as it is, not averaged with the piece that confirmed it.
        """
        if self.window is not None and not rv.range_nis <= self.range_threshold:
            self.log.setdefault(robot, []).append(
                f"{time_s:.1f} s: sighting with {rv.seen}: the two ranges disagree (normalised "
                f"{rv.range_nis:.1f} > {self.range_threshold:.1f}): not merged")
            return None
        return rv if self.offer(robot, time_s, rv.evidence()) is not None else None


def rendezvous_inliers(rv: Rendezvous, target: LandmarkMap, source: LandmarkMap, matches: np.ndarray,
                       config: FusionConfig) -> np.ndarray:
    """(P,) bool: the descriptor ``matches`` (target row, source row) whose local landmark, moved
    by the rendezvous transform, lies within χ²₂(``join_confidence``) of its common-map copy, with
    both landmarks' covariances and the transform's (J_T·Cov T·J_Tᵀ at the landmark)."""
    src = source.means[matches[:, 1], :2]
    jac = transform_jacobian(rv.transform, src)
    cov = (residual_covariances(rv.transform[2], target.covs[matches[:, 0]], source.covs[matches[:, 1]])
           + jac @ rv.transform_cov @ np.swapaxes(jac, -1, -2))
    res = apply_transform(rv.transform, src) - target.means[matches[:, 0], :2]
    return mahalanobis2(res, cov) <= chi2.ppf(config.join_confidence, 2)


def join_rendezvous(
    central: MultiRobotFastSLAM, local: MultiRobotFastSLAM, robot: str, rv: Rendezvous, config: FusionConfig,
) -> JoinResult:
    """Join ``local`` (robot ``robot``) into ``central`` with the rendezvous transform ``rv``.

    Landmarks: descriptor matches between the two best maps that agree after the rendezvous
    transform (:func:`rendezvous_inliers`) are matched (the common copy kept); other matches follow
    ``config.source_outliers``. With ``config.rendezvous_anchor`` (and ``rv.seen`` a robot of
    ``central``) each joined particle's transform is anchored on its own ancestors' poses
    (:func:`anchored_transforms`); otherwise drawn from N(T, Cov T).
    """
    target = LandmarkMap.from_filter(central, z_variance=config.z_variance)
    source = LandmarkMap.from_filter(local, z_variance=config.z_variance)
    pairs = np.zeros((0, 2), np.int64)
    drop = None
    if len(target.means) and len(source.means):
        matches = match_descriptors(target.descriptors, source.descriptors, config.descriptor_threshold, config.mutual)
        if len(matches):
            target = with_marginals(central, target, matches[:, 0])
            source = with_marginals(local, source, matches[:, 1])
            ok = rendezvous_inliers(rv, target, source, matches, config)
            pairs = np.column_stack([target.ids[matches[ok, 0]], source.ids[matches[ok, 1]]])
            if config.source_outliers == "drop":
                drop = source.ids[matches[~ok, 1]]
    anchor = None
    if config.rendezvous_anchor and rv.seen in central.index:
        j, kl = central.index[rv.seen], local.index.get(robot, 0)
        pj, pl = central.poses[:, j].copy(), local.poses[:, kl].copy()

        def anchor(anc_c: np.ndarray, anc_l: np.ndarray) -> np.ndarray:
            return anchored_transforms(pj[anc_c], pl[anc_l], rv.relative, rv.relative_cov, central.rng)

    return join_filters(
        central, local, rv.transform, pairs, config, robot, drop, rv.transform_cov, per_pair=False,
        pose_cov=rv.transform_cov, pair_transforms=anchor,
    )


def join_by_rendezvous(
    central: MultiRobotFastSLAM, local: MultiRobotFastSLAM, robot: str, seen: str,
    z_ij: np.ndarray, z_ji: np.ndarray, cov_ij: np.ndarray, cov_ji: np.ndarray, config: FusionConfig,
) -> tuple[Rendezvous, JoinResult]:
    """Join ``local`` (robot ``robot``, its own frame) into ``central`` from one mutual sighting
    with ``seen`` (a robot of ``central``), trusted as it is: ``z_ij`` is robot's measurement of
    seen, ``z_ji`` seen's of robot (range [m], bearing [rad]) with covariances ``cov_ij``,
    ``cov_ji``. See :class:`RendezvousGate` to require a second, agreeing sighting first."""
    rv = sighting_transform(central, local, seen, z_ij, z_ji, cov_ij, cov_ji)
    return rv, join_rendezvous(central, local, robot, rv, config)
