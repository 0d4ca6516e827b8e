"""Configuration of the multi-robot FastSLAM filter (the only place its defaults are written)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal


@dataclass(frozen=True)
class MotionConfig:
    """Odometry motion model (Thrun et al., Probabilistic Robotics, table 5.6).

    The relative motion between two odometry poses is decomposed into (rot1, trans, rot2); each
    part gets zero-mean Gaussian noise with variance
    ``alpha1·rot1² + alpha2·trans²`` (rotations) and ``alpha3·trans² + alpha4·(rot1² + rot2²)``
    (translation), plus a random walk of density ``sigma_xy_rw`` [m/√s] and ``sigma_theta_rw``
    [rad/√s] over the update's time span, so noise does not depend on how often a robot updates
    and a still robot keeps some spread.
    """

    alpha1: float = 0.01  # rad²/rad²
    alpha2: float = 0.0025  # rad²/m²
    alpha3: float = 0.0025  # m²/m²
    alpha4: float = 0.0001  # m²/rad²
    min_translation: float = 0.01  # m; below it rot1 = 0 (see motion.decompose)
    sigma_xy_rw: float = 0.0  # m/√s
    sigma_theta_rw: float = 0.0  # rad/√s

    def __post_init__(self) -> None:
        for name in ("alpha1", "alpha2", "alpha3", "alpha4", "min_translation", "sigma_xy_rw", "sigma_theta_rw"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0")


@dataclass(frozen=True)
class AssociationConfig:
    """Per-particle data association of 000 section 5 (``ml``) or 001 (``hungarian``).

    ``mahalanobis_gate`` is D0 (a chi-square quantile for the measurement dimension),
    ``descriptor_gate`` is E0 on the squared Euclidean descriptor distance (eq. 16).
    ``new_landmark_log_likelihood``: log p0, the weight factor of an observation that starts a
    landmark; None derives it from the gate: the likelihood of an innovation at D0 with the
    observation's own covariance.
    ``descriptor_trust_gate`` (D1 >= D0, or 0 = off): when no candidate passes D0 but one whose
    descriptor matches (E <= E0) lies within D1, associate with it instead of starting a
    duplicate landmark. For descriptors that identify a landmark for certain (barcodes), this is
    association by known correspondence and lets a drifted robot re-localise; for visual
    descriptors keep it off.
    """

    mode: Literal["ml", "hungarian"] = "ml"
    mahalanobis_gate: float = 11.34  # chi2(3 dof) 0.99
    descriptor_gate: float = 0.5
    new_landmark_log_likelihood: float | None = None
    max_candidates: int = 8
    search_radius_m: float = 1.0
    descriptor_trust_gate: float = 0.0

    def __post_init__(self) -> None:
        if self.mahalanobis_gate <= 0 or self.descriptor_gate < 0:
            raise ValueError("mahalanobis_gate must be > 0 and descriptor_gate >= 0")
        if self.max_candidates < 1:
            raise ValueError("max_candidates must be >= 1")


@dataclass(frozen=True)
class FilterConfig:
    """The multi-robot Rao-Blackwellized particle filter (000, Algorithm 1).

    Attributes:
        num_particles: M.
        proposal: ``fastslam1`` samples poses from the motion model (000); ``fastslam2`` from
            the Gaussian that folds in the step's associated observations (001, Alg. 3).
        observation_model: ``stereo_point`` (3D point in base_link) or ``range_bearing`` (2D).
        resample_threshold: resample when the normalised effective sample size
            (1/Σw²)/M falls below this (000 Alg. 1 line 13).
        initial_pose_sigma: (σx [m], σy [m], σθ [rad]) of the Gaussian the particles start in
            around each robot's known start pose.
        seed: random generator seed.
    """

    num_particles: int = 200
    proposal: Literal["fastslam1", "fastslam2"] = "fastslam1"
    observation_model: Literal["stereo_point", "range_bearing"] = "stereo_point"
    resample_threshold: float = 0.5
    initial_pose_sigma: tuple[float, float, float] = (0.0, 0.0, 0.0)
    seed: int = 0
    initial_capacity: int = 256
    motion: MotionConfig = field(default_factory=MotionConfig)
    association: AssociationConfig = field(default_factory=AssociationConfig)

    def __post_init__(self) -> None:
        if self.num_particles < 1:
            raise ValueError("num_particles must be >= 1")
        if not 0.0 <= self.resample_threshold <= 1.0:
            raise ValueError("resample_threshold must be in [0, 1]")
        if any(s < 0 for s in self.initial_pose_sigma):
            raise ValueError("initial_pose_sigma must be >= 0")
