"""Configuration of the multi-robot FastSLAM filter (the only place its defaults are written)."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Literal


def _refuse_inactive(cfg, names: tuple[str, ...], why: str, prefix: str = "") -> None:
    """Raise ValueError naming the first of ``names`` (fields of ``cfg``) set away from its default
    although it does nothing (``why``): a setting that silently does nothing misleads whoever tunes it."""
    defaults = {f.name: f.default for f in fields(cfg)}
    for name in names:
        if getattr(cfg, name) != defaults[name]:
            raise ValueError(f"{prefix}{name} = {getattr(cfg, name)!r} does nothing {why}")


@dataclass(frozen=True)
class MotionConfig:
    """Odometry motion model (Thrun et al., Probabilistic Robotics, table 5.6).

    The relative motion between two odometry poses is decomposed into (rot1, trans, rot2); each
    part gets zero-mean Gaussian noise with variance
    ``alpha1·rot1² + alpha2·trans²`` (rotations) and ``alpha3·trans² + alpha4·(rot1² + rot2²)``
    (translation), plus a random walk of density ``sigma_xy_rw`` [m/√s] and ``sigma_theta_rw``
    [rad/√s] over the update's time span, so noise does not depend on how often a robot updates,
    plus variances proportional to the distance travelled and the angle turned (the
    ``var_*_per_m`` and ``var_theta_per_rad`` terms: the wheel-odometry model of 002 Table I and
    of the simulator, whose statistics do not depend on the update rate either).
    The random walk accrues only over updates whose odometry reports motion: a robot whose
    odometry reports none stands still (a zero-velocity update; MR.CLAM's robots stand within
    0.5 mm and 0.17° of Vicon for their first 12–16 s of zero velocity), so its pose keeps no
    more spread than it had.
    """

    alpha1: float = 0.01  # rad²/rad²
    alpha2: float = 0.0025  # rad²/m²
    alpha3: float = 0.0025  # m²/m²
    alpha4: float = 0.0001  # m²/rad²
    min_translation: float = 0.01  # m; below it rot1 = 0 (see motion.decompose)
    sigma_xy_rw: float = 0.0  # m/√s
    sigma_theta_rw: float = 0.0  # rad/√s
    var_xy_per_m: float = 0.0  # m²/m, each of x and y in the robot frame
    var_theta_per_m: float = 0.0  # rad²/m
    var_theta_per_rad: float = 0.0  # rad²/rad

    def __post_init__(self) -> None:
        for name in ("alpha1", "alpha2", "alpha3", "alpha4", "min_translation", "sigma_xy_rw", "sigma_theta_rw", "var_xy_per_m", "var_theta_per_m", "var_theta_per_rad"):
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
    association by known correspondence and lets a drifted robot re-localise; and a reading
    whose descriptor matches a landmark the particle holds but which fails even D1 is a misread
    (a second landmark of one identity cannot exist): it neither updates nor starts a landmark
    and is counted (``misread_descriptor``). For visual descriptors keep it off.
    ``candidate_search``: landmarks near the observation (a grid over positions, for
    repetitive visual features) or landmarks whose descriptor is within E0 wherever they are (a
    kd-tree over descriptors, 002 section III; for identifying descriptors such as barcodes).
    ``geometry_weight`` w: the ``ml`` rule picks the gated candidate of least
    E/E0 + w·D/D0; w = 0 is 000's rule (least E), w > 0 breaks near-ties between look-alike
    landmarks (duplicates, repeated textures) by geometry.
    ``min_observations`` is NZ_min of 001 (delayed initialisation): a slot is a candidate, not
    yet a landmark, until it has been associated this many times in a particle; candidates
    neither shape the pose proposal nor weight the particle (their factor is p0), and the
    Hungarian mode matches observations to them only after the landmarks (001 III-D).
    ``outlier_gate`` (FastSLAM 2.0 proposal only; 0 = off): after the pose proposal of a
    particle is fitted to its associated pairs, a pair whose residual at the proposal's mode,
    νᵀZ⁻¹ν with Z = GΣGᵀ + R, exceeds this chi-square quantile is an outlier (a look-alike
    matched to the wrong landmark); the proposal is fitted again without the outliers, and the
    pairs are classified again at the new mode, ``outlier_rounds`` times in all (the outlier
    rejection of ORB-SLAM's pose optimisation). An outlier neither moves the pose, nor updates
    the landmark, nor starts a new one; its weight factor is p0, as for an unexplained
    observation.
    ``track_gate`` (DT >= D0, or 0 = off; ``ml`` mode): an observation whose frontend track id
    was associated with a landmark (or started one) in a particle at one of that robot's last
    ``track_memory`` sets is associated with that landmark again in that particle whenever its
    Mahalanobis distance (motion noise included) is within DT, before any other candidate. The
    frontend follows a track by appearance from image to image, so it stays with its point when
    an odometry step is 3σ off and the map, projected through the predicted pose, falls outside
    D0 for every observation (the robot would then map the whole set again, at the wrong pose);
    the proposal then corrects the pose from those pairs. Track ids are per robot.
    """

    mode: Literal["ml", "hungarian"] = "ml"
    candidate_search: Literal["spatial", "descriptor"] = "spatial"
    mahalanobis_gate: float = 11.34  # chi2(3 dof) 0.99
    descriptor_gate: float = 0.5
    new_landmark_log_likelihood: float | None = None
    max_candidates: int = 8
    search_radius_m: float = 1.0
    descriptor_trust_gate: float = 0.0
    min_observations: int = 1
    geometry_weight: float = 1.0
    outlier_gate: float = 0.0
    outlier_rounds: int = 3
    track_gate: float = 0.0
    track_memory: int = 10

    def __post_init__(self) -> None:
        if self.mahalanobis_gate <= 0 or self.descriptor_gate < 0:
            raise ValueError("mahalanobis_gate must be > 0 and descriptor_gate >= 0")
        if self.max_candidates < 1:
            raise ValueError("max_candidates must be >= 1")
        if self.outlier_gate < 0 or self.outlier_rounds < 1:
            raise ValueError("outlier_gate must be >= 0 and outlier_rounds >= 1")
        if self.track_gate < 0 or self.track_memory < 1:
            raise ValueError("track_gate must be >= 0 and track_memory >= 1")
        if self.mode == "hungarian":
            _refuse_inactive(self, ("geometry_weight", "descriptor_trust_gate", "track_gate"),
                             "with mode hungarian (the ml rule's)")
        if self.candidate_search == "descriptor":
            _refuse_inactive(self, ("search_radius_m",), "with candidate_search descriptor (the spatial search's)")
        if self.outlier_gate == 0:
            _refuse_inactive(self, ("outlier_rounds",), "while outlier_gate is 0 (off)")
        if self.track_gate == 0:
            _refuse_inactive(self, ("track_memory",), "while track_gate is 0 (off)")


@dataclass(frozen=True)
class ExistenceConfig:
    """Existence counter of each landmark (001 section III-F).

    Up by one (to ``max_score``) when the landmark is associated, down by one when it lies in the
    sensor's footprint at the particle's pose (|bearing| <= fov/2, min_range <= range <=
    max_range, planar) but was not observed; removed from the particle below zero. Only sound
    when the frontend reports every feature it sees in that footprint (not a best-B subset).
    """

    enabled: bool = False
    fov_rad: float = 1.2
    min_range: float = 0.3
    max_range: float = 5.0
    max_score: int = 5

    def __post_init__(self) -> None:
        if not 0 < self.fov_rad <= 2 * 3.141592653589793 or self.max_range <= self.min_range:
            raise ValueError("existence footprint: need 0 < fov_rad <= 2π and max_range > min_range")


@dataclass(frozen=True)
class RelocalizationConfig:
    """Re-localising a lost robot (FastSLAM 2.0 proposal only).

    A robot is lost when its associated landmark observations of one update are improbable in
    EVERY particle: the joint normalised innovation νᵀS⁻¹ν (S = HₓPHₓᵀ + blockdiag Z, the
    FastSLAM 2.0 marginal) exceeds the chi-square quantile ``gate_probability`` for its degrees
    of freedom in all particles. That happens when the particles' poses of a robot that went
    unobserved for a while have drifted or collapsed away from its true pose: the one-step motion
    prior of the 2.0 proposal cannot move them back, and the observations would instead drag
    the shared landmarks towards the wrong pose. Then, if the update holds at least
    ``min_landmarks`` associated landmarks in every particle, the robot's pose is drawn again in
    every particle from the proposal whose prior is the one-step motion noise PLUS the
    robot's drift covariance D (the motion model's covariance accumulated since the robot's
    landmark observations last constrained it, kept per robot as an EKF-style covariance:
    D ← F D Fᵀ + Q per motion, D ← (D⁻¹ + HₓᵀZ⁻¹Hₓ)⁻¹ per landmark update), relinearised
    ``iterations`` times at the posterior mode (iterated EKF / Gauss–Newton), and the particle
    is weighted by the Laplace (linearised) marginal of the observations under that prior.
    With fewer landmarks (one range-bearing landmark does not fix a pose) the lost robot's
    observations are set aside: neither weight nor map update nor new landmark.
    """

    enabled: bool = False
    gate_probability: float = 0.999
    min_landmarks: int = 2
    iterations: int = 8

    def __post_init__(self) -> None:
        if not 0.0 < self.gate_probability < 1.0:
            raise ValueError("gate_probability must be in (0, 1)")
        if self.min_landmarks < 1 or self.iterations < 1:
            raise ValueError("min_landmarks and iterations must be >= 1")


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
        sighting_outlier_probability: ε of the robust robot-to-robot likelihood
            (1 − ε)·N(z; ẑ, R) + ε·U, with U uniform over range 0–10 m and bearing ±π, so one
            misread barcode cannot wipe out the particles that are right.
        relocalization: re-drawing a lost robot's pose (see :class:`RelocalizationConfig`).
        defer_motion_noise: while a robot has no measurement (no landmark, no robot-to-robot
            reading involving it), move its poses by the noise-free odometry and accumulate the
            motion noise in a per-robot covariance instead of sampling it every step; the
            accumulated noise is drawn when the robot next has a landmark measurement (as the
            prior of the FastSLAM 2.0 proposal, or by sampling before a FastSLAM 1.0 update);
            a robot-to-robot reading is scored by its marginal under both robots' pending
            covariances and conditions them (an EKF update) without drawing them. No
            measurement depends on those intermediate poses, so this is the same model with
            the noise marginalised (linearised); it stops the weights of the OTHER robots,
            through resampling, from selecting the unobserved robot's random motion noise (its
            weighted mean then drifts away from odometry by tens of degrees on MR.CLAM robot 4
            while it sees nothing for 80 s), and a sighting, which measures where a robot is
            and not where it heads, from leaving its heading to chance.
    """

    num_particles: int = 200
    proposal: Literal["fastslam1", "fastslam2"] = "fastslam1"
    observation_model: Literal["stereo_point", "range_bearing"] = "stereo_point"
    resample_threshold: float = 0.5
    initial_pose_sigma: tuple[float, float, float] = (0.0, 0.0, 0.0)
    seed: int = 0
    sighting_outlier_probability: float = 0.0
    initial_capacity: int = 256
    motion: MotionConfig = field(default_factory=MotionConfig)
    association: AssociationConfig = field(default_factory=AssociationConfig)
    existence: ExistenceConfig = field(default_factory=ExistenceConfig)
    relocalization: RelocalizationConfig = field(default_factory=RelocalizationConfig)
    defer_motion_noise: bool = False

    def __post_init__(self) -> None:
        if self.num_particles < 1:
            raise ValueError("num_particles must be >= 1")
        if not 0.0 <= self.resample_threshold <= 1.0:
            raise ValueError("resample_threshold must be in [0, 1]")
        if any(s < 0 for s in self.initial_pose_sigma):
            raise ValueError("initial_pose_sigma must be >= 0")
        if self.proposal == "fastslam1":
            _refuse_inactive(self.association, ("outlier_gate",), "with proposal fastslam1 (it prunes the "
                             "FastSLAM 2.0 proposal's pairs)", "association.")
            _refuse_inactive(self.relocalization, ("enabled",), "with proposal fastslam1 (it redraws from the "
                             "FastSLAM 2.0 proposal)", "relocalization.")
        if not self.relocalization.enabled:
            _refuse_inactive(self.relocalization, ("gate_probability", "min_landmarks", "iterations"),
                             "while relocalization is off", "relocalization.")
        if not self.existence.enabled:
            _refuse_inactive(self.existence, ("fov_rad", "min_range", "max_range", "max_score"),
                             "while existence is off", "existence.")
