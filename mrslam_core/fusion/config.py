"""Every threshold of map alignment and fusion (the only place their defaults are written)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal


@dataclass(frozen=True)
class FusionConfig:
    """Map alignment (004 section 3), multi-map consistency (3.1), fusion (4) and joining (5).

    Attributes:
        descriptor_threshold: E0, the largest squared Euclidean descriptor distance (000 eq. 16)
            of a putative match.
        mutual: keep only mutual nearest neighbours in descriptor space.
        ransac_iterations: hypotheses drawn (each from 2 matches, the minimal set of a 2D rigid
            transform).
        inlier_distance: a match is an inlier when the transformed source landmark lies within
            this planar distance of the target landmark [m].
        min_inliers: fewest inliers for an alignment to be accepted.
        max_residual: largest inlier RMSE (planar, after refinement) to accept [m].
        min_spread: smallest RMS distance of the inliers from their centroid [m]; below it the
            rotation is not determined (all inliers on one spot).
        refine_iterations: least-squares refits on the inliers (the inlier set is recomputed
            after each).
        weighted: weight each pair in the refinement by 1 / (tr Σ_target,xy + tr Σ_source,xy).
        seed: seed of the RANSAC sampler.
        loop_sigma_xy, loop_sigma_theta: standard deviation [m], [rad] of the prior that ties each
            pairwise RANSAC transform to the multi-map solution (004 section 3.1, E1–E3).
        landmark_sigma: standard deviation of a matched landmark residual [m] in the multi-map
            least squares (004 E4…); None derives it per pair from the landmark covariances.
        source_outliers: what happens to a source landmark whose descriptor matched a target
            landmark but which is not a RANSAC inlier: ``keep`` adds it as a new landmark (visual
            maps, where such a match is usually a wrong match between distinct places), ``drop``
            discards it (identifying descriptors such as barcodes, where it is the same landmark
            mapped badly).
        pair_likelihood: when joining filters, give each joined particle (a drawn pair of a
            central and a local particle) the weight of its matched landmarks agreeing once
            moved by its transform, N(c₁ − c₂; 0, Σ₁ + Σ₂) over the pairs (004 section 5
            resamples the B×B pairs "based on new observations"; this uses the shared landmarks
            as that evidence); otherwise the joined particles start with equal weights.
        pair_likelihood_temper: exponent (0..1] applied to that likelihood, so that a few very
            confident landmarks cannot collapse the joined population onto one pair.
        z_variance: variance [m²] given to z when a planar (2D) map is padded to 3D.
        residual_variance_scale: when joining, the source landmarks' x and y variances grow by
            (scale × the alignment's inlier RMSE)² to hold the transform's own uncertainty
            (0: trust the transform exactly, as 004 does).
        transform_sampling_scale: when joining, each particle draws its own transform from
            N(T, (scale)²·Cov(T)), Cov(T) from the inliers' residuals (0: every particle uses T).
        per_particle_alignment: when joining, refit the transform for each (central particle,
            local particle) pair on its own copies of the inlier landmarks (004 section 5 fuses
            particle by particle; one transform from the best maps fits only the best particle).
        join_pose_sigma: (σx [m], σy [m], σθ [rad]) of independent Gaussian noise given to the
            joined robot's pose in each joined particle, on top of the local particle's pose
            moved by its transform, and added to the drift covariance it joins with: for a local
            filter that is confidently wrong about where the robot stands in its own map
            (MR.CLAM: up to 25° off at the join with a particle spread of 2°), so that the robot's
            next observations of the common map can pick the right pose. (0, 0, 0): the local
            pose as it is. On MR.CLAM it did not help (docs/fusion.md), so it is off there.
        carry_landmarks: when joining, fuse the matched local landmarks into the common map and
            add the local-only ones (004 section 4); False joins the robot's pose only and lets
            it map again in the common filter (tried on MR.CLAM, not better; docs/fusion.md).
        transform_uncertainty: how the alignment's covariance Cov T enters the join. ``drift``:
            only added (propagated to the robot's pose) to the drift covariance the robot joins
            with. ``proposal``: also added to its pending motion covariance, so with deferred
            motion noise and the FastSLAM 2.0 proposal each particle's pose is drawn at the
            robot's next landmark observation from its joined pose widened by Cov T and
            corrected by the common map; and every local landmark moved into the common frame
            gets J_T·Cov T·J_Tᵀ on its x, y covariance (its position depends on T, so the fusion
            does not trust the moved copy over the common one more than T allows).
        transform_cov_source: Cov T used by ``transform_uncertainty``: ``residuals`` (σ² from
            the inliers' residuals, :func:`~mrslam_core.fusion.alignment.transform_covariance`),
            ``landmarks`` (from the inlier landmarks' own covariances, Σ_target + R·Σ_source·Rᵀ
            per pair, :func:`~mrslam_core.fusion.alignment.transform_information_covariance`), or
            ``larger`` (whichever has the larger trace after propagation to the robot's pose).
        max_join_pose_sigma: largest standard deviation [m] of the joined robot's position
            that the alignment alone may cause (√tr of Cov T propagated to the robot's local
            pose, Cov T from ``transform_cov_source``); an alignment above it is refused as
            ill-conditioned (few inliers close together, far from the robot: a small rotation
            error moves the robot a lot) and tried again later. None: no such check.
        min_pair_spread: in the per-pair refit, a (central, local) pair whose own copies of the
            matched landmarks lie within this RMS distance [m] of their centroid (or that holds
            fewer than two of them) uses the alignment's transform instead: two landmarks a
            few centimetres apart do not fix the rotation. None: ``min_spread``.
        rendezvous_window: seconds within which a second mutual sighting must confirm the first
            before a robot joins by rendezvous (:class:`~mrslam_core.fusion.rendezvous.RendezvousGate`);
            None trusts a single sighting.
        rendezvous_gate: probability of the χ²(3) quantile below which two sightings' transforms
            agree (Mahalanobis distance with the sum of their covariances).
        rendezvous_anchor: a rendezvous join places the robot per joined particle relative to
            that particle's own pose of the seen robot, with the sighting's noise drawn per
            particle, and moves each local particle's map with its own pose
            (:func:`~mrslam_core.fusion.rendezvous.anchored_transforms`); False draws one
            transform per particle from N(T, Cov T) around the weighted means.
        pair_draw: how a join draws its M (central, local) ancestor pairs from the M × L pairs
            weighted w_c·w_l: ``grid`` — systematic resampling over the ravelled pair grid (004
            section 5 read literally); its draws are 1/M apart in cumulative weight, so with
            equal central weights every draw lands at the same offset inside its central
            particle's block, i.e. on ONE local particle (MR.CLAM: robot 5 at 35 s joined with 1
            of its 500 local particles) — or ``product``: each side by systematic resampling
            from its own weights, the local draws paired in random order
            (:func:`~mrslam_core.fusion.join.draw_pairs`; the product factorises, so this is
            the same distribution with every local particle represented by its weight).
    """

    descriptor_threshold: float = 0.5
    mutual: bool = True
    ransac_iterations: int = 500
    inlier_distance: float = 0.3
    min_inliers: int = 6
    max_residual: float = 0.2
    min_spread: float = 0.5
    refine_iterations: int = 3
    weighted: bool = True
    seed: int = 0
    loop_sigma_xy: float = 0.2
    loop_sigma_theta: float = 0.02
    landmark_sigma: float | None = None
    source_outliers: Literal["keep", "drop"] = "keep"
    pair_likelihood: bool = False
    pair_likelihood_temper: float = 1.0
    z_variance: float = 1.0
    residual_variance_scale: float = 0.0
    transform_sampling_scale: float = 0.0
    per_particle_alignment: bool = True
    join_pose_sigma: tuple[float, float, float] = (0.0, 0.0, 0.0)
    carry_landmarks: bool = True
    transform_uncertainty: Literal["drift", "proposal"] = "drift"
    transform_cov_source: Literal["residuals", "landmarks", "larger"] = "residuals"
    max_join_pose_sigma: float | None = None
    min_pair_spread: float | None = None
    rendezvous_window: float | None = 10.0
    rendezvous_gate: float = 0.99
    rendezvous_anchor: bool = False
    pair_draw: Literal["grid", "product"] = "grid"

    def __post_init__(self) -> None:
        if self.ransac_iterations < 1 or self.refine_iterations < 0:
            raise ValueError("ransac_iterations must be >= 1 and refine_iterations >= 0")
        if self.min_inliers < 2:
            raise ValueError("min_inliers must be >= 2 (a 2D rigid transform needs two points)")
        if self.inlier_distance <= 0 or self.max_residual <= 0 or self.min_spread < 0:
            raise ValueError("inlier_distance and max_residual must be > 0, min_spread >= 0")
        if self.descriptor_threshold < 0:
            raise ValueError("descriptor_threshold must be >= 0")
        if self.loop_sigma_xy <= 0 or self.loop_sigma_theta <= 0:
            raise ValueError("loop sigmas must be > 0")
        if self.landmark_sigma is not None and self.landmark_sigma <= 0:
            raise ValueError("landmark_sigma must be > 0 or None")
        if not 0 < self.pair_likelihood_temper <= 1:
            raise ValueError("pair_likelihood_temper must be in (0, 1]")
        if self.residual_variance_scale < 0 or self.transform_sampling_scale < 0:
            raise ValueError("residual_variance_scale and transform_sampling_scale must be >= 0")
        if len(self.join_pose_sigma) != 3 or min(self.join_pose_sigma) < 0:
            raise ValueError("join_pose_sigma must be three values >= 0")
        if self.max_join_pose_sigma is not None and self.max_join_pose_sigma <= 0:
            raise ValueError("max_join_pose_sigma must be > 0 or None")
        if self.min_pair_spread is not None and self.min_pair_spread < 0:
            raise ValueError("min_pair_spread must be >= 0 or None")
        if self.rendezvous_window is not None and self.rendezvous_window <= 0:
            raise ValueError("rendezvous_window must be > 0 or None")
        if not 0 < self.rendezvous_gate < 1:
            raise ValueError("rendezvous_gate must be in (0, 1)")
        if self.z_variance <= 0:
            raise ValueError("z_variance must be > 0")
