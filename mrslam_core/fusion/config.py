"""Every threshold of map alignment and fusion (the only place their defaults are written)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal


@dataclass(frozen=True)
class FusionConfig:
    """Map alignment (004 section 3), multi-map consistency (3.1), fusion (4) and joining (5).

    ``inlier_distance``, ``min_inliers``, ``max_residual`` and ``min_spread`` are the metre
    thresholds of :func:`~mrslam_core.fusion.alignment.ransac_align` (re-localisation and map
    checks of the central mapper, the multi-map solver); a join of a robot with an unknown start
    is decided by the χ² tests of :mod:`~mrslam_core.fusion.acceptance` (``join_confidence``).

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
        carry_landmarks: when joining, carry the local map over: a matched landmark keeps the
            common copy (a particle that lacks it gets the moved local copy), the local-only ones
            are added; False joins the robot's pose only and lets it map again in the common
            filter (tried on MR.CLAM, not better; docs/fusion.md).
        transform_uncertainty: how the alignment's covariance Cov T enters the join. ``drift``:
            only added (propagated to the robot's pose) to the drift covariance the robot joins
            with. ``proposal``: also added to its pending motion covariance, so with deferred
            motion noise and the FastSLAM 2.0 proposal each particle's pose is drawn at the
            robot's next landmark observation from its joined pose widened by Cov T and
            corrected by the common map; and every local landmark moved into the common frame
            gets J_T·Cov T·J_Tᵀ on its x, y covariance (its position depends on T, so the fusion
            does not trust the moved copy over the common one more than T allows).
        min_pair_spread: in the per-pair refit, a (central, local) pair whose own copies of the
            matched landmarks lie within this RMS distance [m] of their centroid (or that holds
            fewer than two of them) uses the alignment's transform instead: two landmarks a
            few centimetres apart do not fix the rotation. None: ``min_spread``.
        join_confidence: p of every χ² test that decides a join of a robot with an unknown
            start (:mod:`~mrslam_core.fusion.acceptance`): a matched landmark pair is an inlier
            within χ²₂(p) of its residual covariance, the inliers' residual sum within
            χ²_{2n−3}(p), the chance of the inlier set under a wrong transform at most 1 − p,
            two pieces of evidence agree within χ²₃(p) of their summed covariances, and the two
            ranges of a mutual sighting within χ²₁(p).
        evidence_window: seconds over which held evidence for a join (a mutual sighting, a weak
            alignment) can confirm a new piece (:class:`~mrslam_core.fusion.acceptance.JoinGate`);
            None trusts every piece that passes its own tests.
        rendezvous_anchor: a rendezvous join places the robot per joined particle relative to
            that particle's own pose of the seen robot, with the sighting's noise drawn per
            particle, and moves each local particle's map with its own pose
            (:func:`~mrslam_core.fusion.rendezvous.anchored_transforms`); False draws one
            transform per particle from N(T, Cov T) around the weighted means.
        sighting_pair_window: two robots' readings of each other at most this far apart are one
            mutual sighting (their motion in between is not modelled; MR.CLAM's filter step) [s].
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
    per_particle_alignment: bool = True
    join_pose_sigma: tuple[float, float, float] = (0.0, 0.0, 0.0)
    carry_landmarks: bool = True
    transform_uncertainty: Literal["drift", "proposal"] = "drift"
    min_pair_spread: float | None = None
    join_confidence: float = 0.99
    evidence_window: float | None = 10.0
    rendezvous_anchor: bool = False
    sighting_pair_window: float = 0.2

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
        if len(self.join_pose_sigma) != 3 or min(self.join_pose_sigma) < 0:
            raise ValueError("join_pose_sigma must be three values >= 0")
        if self.min_pair_spread is not None and self.min_pair_spread < 0:
            raise ValueError("min_pair_spread must be >= 0 or None")
        if self.evidence_window is not None and self.evidence_window <= 0:
            raise ValueError("evidence_window must be > 0 or None")
        if not self.sighting_pair_window >= 0:
            raise ValueError("sighting_pair_window must be >= 0")
        if not 0 < self.join_confidence < 1:
            raise ValueError("join_confidence must be in (0, 1)")
        if self.z_variance <= 0:
            raise ValueError("z_variance must be > 0")
