"""The centralised multi-robot Rao-Blackwellized particle filter (000, sections 3 and 5, Alg. 1).

Every particle holds the SE(2) poses of all K robots and ONE landmark map shared by the team, so a
robot localises against landmarks that another robot mapped. Per robot update: sample the robot's
pose from the odometry motion model, associate each observation per particle (Mahalanobis gate D0,
then the smallest descriptor distance E below E0, else a new landmark), update associated
landmarks with the EKF (eqs. 6–11), initialise new ones with covariance G⁻¹RG⁻ᵀ, and weight the
particle by the product of the observation likelihoods (eq. 13). The team weight is the product
over robots (a sum in log space); the filter resamples (low variance) when the normalised
effective sample size falls below a threshold; the best particle maximises the summed log weights
(eq. 14).

All particle state is arrays: poses (M, K, 3), log weights (M,), and a :class:`LandmarkStore`.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from mrslam_core.geometry.se2 import wrap_angle
from mrslam_core.linalg import is_positive_definite, quad_form, sym_inv_det
from mrslam_core.slam.association import associate_hungarian, associate_ml, resolve_conflicts
from mrslam_core.slam.association_kernels import chosen, ml_cost
from mrslam_core.slam.config import FilterConfig
from mrslam_core.slam.landmarks import LandmarkStore
from mrslam_core.slam.models import ObservationModel, RangeBearingModel, make_model
from mrslam_core.slam.motion import predict_motion, sample_motion
from mrslam_core.slam.proposal_kernels import sum_terms
from mrslam_core.slam.resampling import (
    copy_plan,
    effective_sample_fraction,
    low_variance_indices,
    normalise_log_weights,
)
from mrslam_core.slam.tracks import TrackMemory
from mrslam_core.types import ObservationSet, RobotSighting

LOG_2PI = float(np.log(2.0 * np.pi))
#: Inputs beyond these bounds are dropped as implausible (found by fuzzing: larger finite values
#: overflow the motion and EKF arithmetic or the float32 landmark store): |odometry| and
#: |measurement| components [m or rad], and measurement/sighting variances [m², rad²].
MAX_ABS_INPUT = 1e4
VARIANCE_BOUNDS = (1e-12, 1e8)


class FilterInputError(ValueError):
    """An update the filter cannot use at all (unknown robot, malformed arrays)."""


@dataclass(frozen=True)
class RobotUpdate:
    """One robot's input to a team step.

    Attributes:
        robot: robot name.
        stamp_ns: time of the update (ns); must increase per robot.
        odometry: (3,) relative motion (dx [m], dy [m], dθ [rad]) since the robot's previous
            update, in the robot's base frame at the previous update.
        observations: landmark observations at ``stamp_ns`` (or None).
        sightings: range-bearing measurements of other robots at ``stamp_ns``.
    """

    robot: str
    stamp_ns: int
    odometry: np.ndarray
    observations: ObservationSet | None = None
    sightings: Sequence[RobotSighting] = ()


@dataclass(frozen=True)
class StepResult:
    """What a team step did."""

    resampled: bool
    neff_fraction: float
    associated: int
    new_landmarks: int
    dropped: dict[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class Estimate:
    """The filter's answer after a step.

    Attributes:
        best: index of the best particle (eq. 14).
        poses: (K, 3) robot poses of the best particle, map frame.
        mean: (K, 3) weighted mean poses (circular mean for θ).
        cov: (K, 3, 3) weighted pose covariances.
    """

    best: int
    poses: np.ndarray
    mean: np.ndarray
    cov: np.ndarray


class MultiRobotFastSLAM:
    """Multi-robot FastSLAM with a shared map.

    Args:
        config: filter parameters.
        robots: robot names, in a fixed order (the K axis of the pose array).
        start_poses: (K, 3) known start poses in the map frame.
        model: observation model; default from ``config.observation_model``.
    """

    def __init__(
        self,
        config: FilterConfig,
        robots: Sequence[str],
        start_poses: np.ndarray,
        model: ObservationModel | None = None,
    ):
        start_poses = np.asarray(start_poses, dtype=float)
        if len(set(robots)) != len(robots) or not robots:
            raise FilterInputError(f"robot names must be unique and non-empty, got {robots!r}")
        if start_poses.shape != (len(robots), 3) or not np.isfinite(start_poses).all():
            raise FilterInputError(f"start_poses must be finite ({len(robots)}, 3)")
        self.config = config
        self.robots = list(robots)
        self.index = {name: k for k, name in enumerate(self.robots)}
        self.model = model or make_model(config.observation_model)
        self.rng = np.random.default_rng(config.seed)
        m = config.num_particles
        noise = self.rng.standard_normal((m, len(robots), 3)) * np.asarray(config.initial_pose_sigma)
        self.poses = start_poses[None] + noise
        self.poses[..., 2] = wrap_angle(self.poses[..., 2])
        self.log_w = np.full(m, -np.log(m))
        self.score = np.zeros(m)
        self.landmarks = LandmarkStore(m, self.model.dim, 0, config.initial_capacity)
        self.last_stamp: dict[str, int] = {}
        self.dropped: Counter[str] = Counter()
        self.steps = 0
        self.resamples = 0
        self.removed_landmarks = 0
        self.relocalizations = 0
        #: (particle, observation) pairs the proposal left out as outliers (association.outlier_gate)
        self.outlier_pairs = 0
        #: per robot index: drift covariance D (3, 3) of its pose since its landmark
        #: observations last constrained it (see RelocalizationConfig); missing = initial σ².
        self.drift_cov: dict[int, np.ndarray] = {}
        #: per robot index: motion noise (3, 3), map frame, accumulated but not yet sampled
        #: (``defer_motion_noise``); missing = none.
        self.pending_cov: dict[int, np.ndarray] = {}
        #: per robot index, the landmark its recent frontend tracks went to (``track_gate``)
        self.tracks: dict[int, TrackMemory] = {}
        self._noise_drawn = True

    # ------------------------------------------------------------------ public API
    @property
    def num_particles(self) -> int:
        return self.poses.shape[0]

    def step(self, updates: Sequence[RobotUpdate]) -> StepResult:
        """One team step: every robot's update in order, then resampling if due.

        Updates that cannot be used (unknown robot, non-finite odometry, a stamp not later than
        the robot's previous one) are dropped and counted in :attr:`dropped`; the state is
        untouched by them. Observation rows with non-finite values or covariances that are not
        positive definite are dropped and counted too, as are values beyond
        :data:`MAX_ABS_INPUT` and variances outside :data:`VARIANCE_BOUNDS`. A batch with a
        wrong measurement dimension or descriptor length raises FilterInputError before any
        state changes.
        """
        self._check_batch(updates)
        before = sum(self.dropped.values())
        associated = created = 0
        for upd in updates:
            if not self._accept(upd):
                continue
            k = self.index[upd.robot]
            last = self.last_stamp.get(upd.robot)
            dt = 0.0 if last is None else (upd.stamp_ns - last) * 1e-9
            self.last_stamp[upd.robot] = upd.stamp_ns
            obs = upd.observations
            odo = np.asarray(upd.odometry, float)
            log_l = np.zeros(self.num_particles)
            if self.config.relocalization.enabled:
                self._propagate_drift(k, odo, dt)
            if self.config.defer_motion_noise:
                self.poses[:, k], _ = predict_motion(self.poses[:, k], odo, self.config.motion, dt)
                self.pending_cov[k] = self._propagate(self.pending_cov.get(k, np.zeros((3, 3))), k, odo, dt)
                a = c = 0
                if obs is not None and len(obs):
                    if self.config.proposal == "fastslam2":
                        self._noise_drawn = True
                        p_x = np.broadcast_to(self.pending_cov[k], (self.num_particles, 3, 3)).copy()
                        a, c = self._observe(k, obs, log_l, p_x)
                        if self._noise_drawn:
                            self.pending_cov.pop(k, None)
                    else:
                        self._draw_pending(k)
                        a, c = self._observe(k, obs, log_l)
            elif self.config.proposal == "fastslam2" and obs is not None and len(obs):
                self.poses[:, k], p_x = predict_motion(self.poses[:, k], odo, self.config.motion, dt)
                a, c = self._observe(k, obs, log_l, p_x)
            else:
                self.poses[:, k] = sample_motion(self.poses[:, k], odo, self.config.motion, self.rng, dt)
                a = c = 0
                if obs is not None and len(obs):
                    a, c = self._observe(k, obs, log_l)
            associated += a
            created += c
            for sighting in upd.sightings:
                self._observe_robot(k, sighting, log_l)
            self.log_w = normalise_log_weights(self.log_w + log_l)
            self.score += log_l
        neff = effective_sample_fraction(self.log_w)
        resampled = neff < self.config.resample_threshold
        if resampled:
            self._resample()
        self.steps += 1
        after = dict(self.dropped)
        dropped_now = sum(after.values()) - before
        return StepResult(
            resampled, neff, associated, created, {"total": dropped_now} if dropped_now else {}
        )

    def best_particle(self) -> int:
        """argmax of the summed log likelihoods over the run (eq. 14)."""
        return int(np.argmax(self.score))

    def estimate(self) -> Estimate:
        """Best particle's poses and the weighted mean and covariance of every robot's pose."""
        w = np.exp(self.log_w)
        best = self.best_particle()
        mean_xy = np.einsum("m,mkd->kd", w, self.poses[..., :2])
        sin = np.einsum("m,mk->k", w, np.sin(self.poses[..., 2]))
        cos = np.einsum("m,mk->k", w, np.cos(self.poses[..., 2]))
        mean = np.concatenate([mean_xy, np.arctan2(sin, cos)[:, None]], axis=1)
        dev = self.poses - mean[None]
        dev[..., 2] = wrap_angle(dev[..., 2])
        cov = np.einsum("m,mki,mkj->kij", w, dev, dev)
        for k, pending in self.pending_cov.items():  # motion noise not yet drawn
            cov[k] += pending
        return Estimate(best, self.poses[best].copy(), mean, cov)

    def best_map(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Landmarks of the best particle: (slots, means (N, dim), covs, descriptors, counts)."""
        best = self.best_particle()
        slots, mean, cov, desc = self.landmarks.particle_map(best)
        (count,) = self.landmarks.gather(np.full(slots.size, best), slots, ("count",))
        return slots, mean, cov, desc, count

    # ------------------------------------------------------------------ internals
    def _check_batch(self, updates: Sequence[RobotUpdate]) -> None:
        """Raise FilterInputError for observations no update may start from (a measurement
        dimension other than the model's, descriptor lengths that differ from the map's or
        within the batch), before the step changes any state, so a failed step changes nothing."""
        d_map = self.landmarks.descriptor_dim if self.landmarks.size else None
        for upd in updates:
            obs = upd.observations
            if obs is None or upd.robot not in self.index or not len(obs):
                continue
            if obs.z.shape[1] != self.model.dim:
                raise FilterInputError(
                    f"{obs.robot}: observations have dimension {obs.z.shape[1]}, model "
                    f"{self.model.name} needs {self.model.dim}"
                )
            d = obs.descriptors.shape[1]
            if d_map is not None and d != d_map:
                raise FilterInputError(
                    f"{obs.robot}: descriptor length {d} differs from the map's {d_map}"
                )
            d_map = d

    def _accept(self, upd: RobotUpdate) -> bool:
        if upd.robot not in self.index:
            self.dropped["unknown_robot"] += 1
            return False
        odo = np.asarray(upd.odometry, dtype=float)
        if odo.shape != (3,) or not np.isfinite(odo).all() or np.abs(odo).max() > MAX_ABS_INPUT:
            self.dropped["bad_odometry"] += 1
            return False
        last = self.last_stamp.get(upd.robot)
        if last is not None and upd.stamp_ns <= last:
            self.dropped["stale_stamp"] += 1
            return False
        return True

    def _clean(self, obs: ObservationSet) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        dim = self.model.dim
        if obs.z.shape[1] != dim:
            raise FilterInputError(
                f"{obs.robot}: observations have dimension {obs.z.shape[1]}, model "
                f"{self.model.name} needs {dim}"
            )
        ok = np.isfinite(obs.z).all(axis=1) & is_positive_definite(obs.cov)
        ok &= (np.abs(obs.z) <= MAX_ABS_INPUT).all(axis=1)
        var = np.diagonal(obs.cov, axis1=1, axis2=2)
        ok &= ((var >= VARIANCE_BOUNDS[0]) & (var <= VARIANCE_BOUNDS[1])).all(axis=1)
        ok &= np.isfinite(obs.descriptors).all(axis=1)
        if (~ok).any():
            self.dropped["bad_observation"] += int((~ok).sum())
        return obs.z[ok], obs.cov[ok], obs.descriptors[ok], obs.track_ids[ok]

    def _search_radius(self, k: int, z: np.ndarray) -> tuple[np.ndarray, float]:
        """Mean pose of robot k and a radius that covers every particle's view of the batch."""
        p = self.poses[:, k]
        w = np.exp(self.log_w)
        mean = np.empty(3)
        mean[:2] = w @ p[:, :2]
        mean[2] = np.arctan2(w @ np.sin(p[:, 2]), w @ np.cos(p[:, 2]))
        pos_spread = np.sqrt(((p[:, :2] - mean[:2]) ** 2).sum(1).max())
        ang_spread = np.abs(wrap_angle(p[:, 2] - mean[2])).max()
        if isinstance(self.model, RangeBearingModel):
            reach = float(z[:, 0].max())
        else:
            reach = float(np.sqrt((z[:, :2] ** 2).sum(1)).max())
        radius = self.config.association.search_radius_m + pos_spread + reach * ang_spread
        return mean, radius

    def _observe(
        self, k: int, obs: ObservationSet, log_l: np.ndarray, motion_cov: np.ndarray | None = None
    ) -> tuple[int, int]:
        """Associate, update and create landmarks for robot k; adds log likelihoods to log_l.

        With ``motion_cov`` (M, 3, 3) the poses of robot k are the noise-free predictions and
        the pose is drawn from the FastSLAM 2.0 proposal after association; otherwise they are
        already samples of the motion model (FastSLAM 1.0).
        """
        z, r, desc, tracks = self._clean(obs)
        b = z.shape[0]
        if b == 0:
            if motion_cov is not None:
                empty = np.zeros(0, np.int64)
                self._sample_proposal(k, empty, empty, z, r, empty, motion_cov, log_l)
            return 0, 0
        cfg = self.config.association
        store = self.landmarks
        model = self.model
        dim = model.dim
        m = self.num_particles
        if store.size == 0 and store.descriptor_dim != desc.shape[1]:
            store.allocate(0, desc[:0])
        if desc.shape[1] != store.descriptor_dim:
            raise FilterInputError(
                f"{obs.robot}: descriptor length {desc.shape[1]} differs from the map's "
                f"{store.descriptor_dim}"
            )
        poses = self.poses[:, k]
        _, r_det = sym_inv_det(r)
        log_p0 = (
            np.full(b, cfg.new_landmark_log_likelihood)
            if cfg.new_landmark_log_likelihood is not None
            else -0.5 * (cfg.mahalanobis_gate + dim * LOG_2PI + np.log(r_det))
        )

        mean_pose, radius = self._search_radius(k, z)
        world, _ = model.inverse(mean_pose, z)
        if cfg.candidate_search == "descriptor":
            cand = store.descriptor_candidates(desc, 4 * cfg.max_candidates, cfg.descriptor_gate)
        else:
            cand = store.candidates(world, 4 * cfg.max_candidates, radius)  # (B, 4C), nearest first
        cand, e = self._descriptor_filter(cand, desc)
        cand, e = cand[:, : cfg.max_candidates], e[:, : cfg.max_candidates]
        memory = None
        if cfg.track_gate > 0 and cfg.mode == "ml":
            memory = self.tracks.setdefault(k, TrackMemory(m, cfg.track_memory))
            track_slot = memory.lookup(tracks)  # (M, B)
            cand, e = self._with_track_candidates(cand, e, desc, track_slot)
        pair = np.full((m, b), -1, np.int64)
        misread = None
        vb, vc = np.nonzero(cand >= 0)  # the V (observation, candidate) pairs worth scoring
        vslots = cand[vb, vc]
        if vb.size:
            rows = store.rows(np.arange(m)[:, None], vslots[None])  # (M, V) pool rows of the pairs
            (held,) = store.gather_rows(rows, ("exists",))
            if cfg.min_observations > 1:
                (count,) = store.gather_rows(rows, ("count",))
                confirmed = count >= cfg.min_observations
            else:
                confirmed = held
            maha, log_norm = model.score_rows(
                poses, z, r, store.field_rows("mean"), store.field_rows("cov"), rows, vb, motion_cov,
                with_norm=cfg.mode != "ml",
            )
            if cfg.mode == "ml":
                geo = cfg.geometry_weight * cfg.descriptor_gate / cfg.mahalanobis_gate
                cost = np.empty(maha.shape)
                ml_cost(
                    maha, held, confirmed, np.ascontiguousarray(e[vb, vc]), cfg.mahalanobis_gate, geo + 1e-9,
                    cfg.descriptor_trust_gate, np.zeros((0, 0), np.int64) if memory is None else track_slot,
                    vslots, vb, cfg.track_gate, cost,
                )
                pair = associate_ml(cost, vb, vc, b, cand.shape[1])
                if np.unique(vslots).size < vslots.size:  # else no two observations share a slot
                    pair, n = resolve_conflicts(pair, vslots, cost)
                    if n:
                        self.dropped["duplicate_association"] += n
                if cfg.descriptor_trust_gate > cfg.mahalanobis_gate:
                    misread = self._misread(pair, held, vb, b)
            else:
                feasible = held & (maha <= cfg.mahalanobis_gate)
                ll = np.where(feasible, -0.5 * (maha + log_norm), -np.inf)
                pair = associate_hungarian(np.where(confirmed, ll, -np.inf), vb, vslots, log_p0)
                left = (pair < 0)[:, vb]
                if (left & ~confirmed & feasible).any():  # leftovers against candidates (001 III-D)
                    second = associate_hungarian(np.where(left & ~confirmed, ll, -np.inf), vb, vslots, log_p0)
                    pair = np.where(pair >= 0, pair, second)

        assoc = pair >= 0
        rejected = np.zeros_like(assoc) if misread is None else misread
        mi = bi = np.zeros(0, np.int64)
        if vb.size:
            # read: the landmarks' rows before the write (shared: in cache)
            mi, bi, slots, conf, read = chosen(
                pair, np.ascontiguousarray(vslots, np.int64), np.ascontiguousarray(confirmed), rows
            )
        if mi.size:
            if motion_cov is not None:
                poses, usable, inlier = self._sample_proposal(
                    k, mi[conf], bi[conf], z, r, read[conf], motion_cov, log_l
                )
                if not usable:  # a lost robot's observations that cannot re-localise it
                    return 0, 0
                if not inlier.all():
                    out = np.flatnonzero(conf)[~inlier]
                    assoc[mi[out], bi[out]] = False
                    rejected[mi[out], bi[out]] = True
                    self.outlier_pairs += out.size
                    keep = np.ones(mi.size, bool)
                    keep[out] = False
                    mi, bi, slots, conf, read = (a[keep] for a in (mi, bi, slots, conf, read))
            new_mu, new_cov, d_sel, norm_sel = model.update_rows(
                poses, z, r, mi, bi, store.field_rows("mean"), store.field_rows("cov"), read
            )
            store.write(mi, slots, mean=new_mu, cov=new_cov, seen=self.config.existence.max_score)
            if motion_cov is None:
                log_l += np.bincount(mi[conf], -0.5 * (d_sel[conf] + norm_sel[conf]), m)
            if (~conf).any():
                log_l += np.bincount(mi[~conf], log_p0[bi[~conf]], m)
            store.set_reference(slots, new_mu)
        elif motion_cov is not None:
            poses, _, _ = self._sample_proposal(k, mi, mi, z, r, mi, motion_cov, log_l)
        if self.config.existence.enabled:
            self._update_existence(poses, mean_pose, radius, mi, vslots[pair[mi, bi]] if mi.size else mi)

        log_l += (~assoc * log_p0[None]).sum(axis=1)
        created, new_slots = self._create(poses, z, r, desc, tracks, ~assoc & ~rejected, obs.stamp_ns, k)
        if memory is not None:
            kept = np.full((m, b), -1, np.int64)
            if mi.size:
                kept[mi, bi] = slots
            memory.record(tracks, np.where(kept >= 0, kept, new_slots))
        return int(assoc.sum()), created

    def _misread(self, pair: np.ndarray, held: np.ndarray, vb: np.ndarray, b: int) -> np.ndarray:
        """(M, B) observations that a particle's map holds a landmark of the same identifying
        descriptor for (``descriptor_trust_gate`` on) but that fail even the trust gate D1: with
        descriptors that identify a landmark for certain, a second landmark of that identity
        cannot exist, so the reading is wrong (a misread barcode); it neither updates nor starts
        a landmark, and is counted as ``misread_descriptor``."""
        same = np.zeros((vb.size, b))
        same[np.arange(vb.size), vb] = 1.0
        misread = ((held @ same) > 0) & (pair < 0)
        if misread.any():
            self.dropped["misread_descriptor"] += int(misread.any(axis=0).sum())
        return misread

    def _with_track_candidates(
        self, cand: np.ndarray, e: np.ndarray, desc: np.ndarray, track_slot: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Add to each observation's candidates (B, C) the two slots its track went to in most
        particles (``track_slot`` (M, B), −1: none), whatever their distance or descriptor;
        returns (cand, E) of width C + 2 (−1 / unused where there are fewer). In a particle whose
        own memory names another slot (or none) they are scored like any candidate, by E and D,
        without the E0 cut of :meth:`_descriptor_filter` (the track says they are the point)."""
        b = cand.shape[0]
        extra = np.full((b, 2), -1, np.int64)
        for j in np.flatnonzero((track_slot >= 0).any(axis=0)):
            values, counts = np.unique(track_slot[:, j], return_counts=True)
            counts[values < 0] = 0
            top = values[np.argsort(-counts, kind="stable")[:2]]
            top = top[top >= 0]
            extra[j, : top.size] = top
        if not (extra >= 0).any():
            return cand, e
        dup = (cand[:, :, None] == extra[:, None, :]) & (extra[:, None, :] >= 0)
        cand = np.where(dup.any(axis=2), -1, cand)
        valid = extra >= 0
        if desc.shape[1]:
            e_extra = ((desc[:, None, :] - self.landmarks.descriptor[np.where(valid, extra, 0)]) ** 2).sum(-1)
        else:
            e_extra = np.zeros(extra.shape)
        return np.concatenate([extra, cand], axis=1), np.concatenate([np.where(valid, e_extra, 0.0), e], axis=1)

    def _sample_proposal(
        self, k: int, mi: np.ndarray, bi: np.ndarray, z: np.ndarray, r: np.ndarray, rows: np.ndarray,
        motion_cov: np.ndarray, log_l: np.ndarray,
    ) -> tuple[np.ndarray, bool]:
        """FastSLAM 2.0: draw robot k's pose from the Gaussian that folds in its associated
        observations, and add the joint marginal log likelihood of those observations.

        The current poses of robot k are the noise-free motion predictions x̂. With
        Hₓ, Z = G Σ Gᵀ + R and ν = z − ẑ(x̂) of each associated pair (P of them, particle mi):
        Λ = P⁻¹ + Σ HₓᵀZ⁻¹Hₓ, η = Σ HₓᵀZ⁻¹ν, pose ~ N(x̂ + Λ⁻¹η, Λ⁻¹) (001 Alg. 3, the
        measurements of one step folded in at once). The weight is the exact marginal
        N(ν; 0, HₓPHₓᵀ + blockdiag Z): by the determinant lemma and Woodbury,
        log|S| = Σ log|Z| + log|P| + log|Λ| and νᵀS⁻¹ν = Σ νᵀZ⁻¹ν − ηᵀΛ⁻¹η.
        A robot whose observations are improbable in every particle is re-localised or its
        observations set aside (see :class:`RelocalizationConfig`).

        With ``association.outlier_gate`` set, pairs whose residual at the mode fails the gate
        are left out and the proposal fitted again (see :class:`AssociationConfig`).

        Args:
            k: the robot.
            mi, bi, rows: (P,) particle, observation and landmark pool row of each pair.
            z, r: (B, dim) observations and (B, dim, dim) covariances.
            motion_cov: (M, 3, 3) the prior covariance P.
            log_l: (M,) log likelihoods, added to.

        Returns:
            (the new poses of robot k (M, 3), also written into ``self.poses``; False when the
            observations were set aside because the robot is lost and they cannot fix its pose;
            (P,) bool, the pairs the proposal kept).
        """
        m = self.num_particles
        x_hat = self.poses[:, k].copy()
        reloc = self.config.relocalization
        (mode, cov, ll, nis, info), terms, lam0, p_det = self._fold(x_hat, mi, bi, z, r, rows, motion_cov, 1)
        usable = True
        inlier = np.ones(mi.size, bool)
        if mi.size:
            counts = np.bincount(mi, minlength=m)
            w = np.exp(self.log_w)
            lost = False
            if reloc.enabled and counts.min() > 0:
                dofs, inv = np.unique(self.model.dim * counts, return_inverse=True)
                gate = chi2.ppf(reloc.gate_probability, dofs)[inv]  # a few distinct dofs only
                lost = bool(np.all(nis > gate))
            if lost and counts.min() >= reloc.min_landmarks:
                prior = np.broadcast_to(self._drift(k), motion_cov.shape).copy()
                if not self.config.defer_motion_noise:  # else D already holds the unsampled noise
                    prior += motion_cov
                (mode, cov, ll, nis, info), _, _, _ = self._fold(x_hat, mi, bi, z, r, rows, prior, reloc.iterations)
                self.relocalizations += 1
                self._inform_drift(k, np.einsum("m,mij->ij", w, prior), np.einsum("m,mij->ij", w, info))
            elif lost:
                usable = False
                self.dropped["lost_robot_observation"] += int(counts.min())
                if self.config.defer_motion_noise:  # the noise stays pending
                    self._noise_drawn = False
                    return x_hat, usable, inlier
                mode, cov = x_hat, motion_cov
            else:
                gate = self.config.association.outlier_gate
                if gate > 0:
                    inlier, (mode, cov, ll, nis, info) = self._robust_fold(
                        x_hat, mi, terms, lam0, p_det, mode, gate
                    )
                    counts = np.bincount(mi[inlier], minlength=m)
                log_l += np.where(counts > 0, ll, 0.0)
                if reloc.enabled:
                    self._inform_drift(k, self._drift(k), np.einsum("m,mij->ij", w, info))
            if lost and usable:
                log_l += ll
        chol = np.linalg.cholesky(cov + 1e-12 * np.eye(3))
        new = mode + (chol @ self.rng.standard_normal((m, 3, 1)))[..., 0]
        new[:, 2] = wrap_angle(new[:, 2])
        self.poses[:, k] = new
        return new, usable, inlier

    def _robust_fold(
        self, x_hat: np.ndarray, mi: np.ndarray, terms: tuple, lam0: np.ndarray, p_det: np.ndarray,
        mode: np.ndarray, gate: float,
    ) -> tuple[np.ndarray, tuple]:
        """Classify the pairs at ``mode`` by their residual νᵀZ⁻¹ν against ``gate``, refit the
        proposal on the inliers, and repeat (``association.outlier_rounds`` in all).

        The residual at the mode is the linearised one the proposal itself uses,
        ν − Hₓ(mode − x̂), so the rounds re-sum the per-pair ``terms`` of :meth:`_fold` and never
        evaluate the observation model again.

        Returns:
            ((P,) inlier mask, the :meth:`_combine` result on the final inliers).
        """
        nu, zinv, hx = terms[4:]
        inlier = None
        for _ in range(self.config.association.outlier_rounds):
            dx = mode[mi] - x_hat[mi]
            dx[:, 2] = wrap_angle(dx[:, 2])
            now = quad_form(nu - (hx @ dx[..., None])[..., 0], zinv) <= gate
            if inlier is not None and np.array_equal(now, inlier):
                break
            inlier = now
            fit = self._combine(x_hat, mi, terms, lam0, p_det, inlier)
            mode = fit[0]
        return inlier, fit

    def _combine(
        self, x_hat: np.ndarray, mi: np.ndarray, terms: tuple, lam0: np.ndarray, p_det: np.ndarray,
        keep: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The proposal from the prior information ``lam0`` (M, 3, 3) and the per-pair ``terms``
        of :meth:`_fold` (of the pairs ``keep`` selects, default all): (mode, Λ⁻¹, log
        marginal likelihood, νᵀS⁻¹ν, observation information), as :meth:`_fold` returns."""
        m = x_hat.shape[0]
        info_p, eta_p, quad_p, norm_p = terms[:4]
        if keep is not None:
            mi, info_p, eta_p, quad_p, norm_p = (a[keep] for a in (mi, info_p, eta_p, quad_p, norm_p))
        info, eta, quad, logdet = sum_terms(
            np.ascontiguousarray(mi, np.int64), np.ascontiguousarray(info_p.reshape(-1, 9), float),
            np.ascontiguousarray(eta_p, float), np.ascontiguousarray(quad_p, float),
            np.ascontiguousarray(norm_p, float), m,
        )
        lam = lam0 + info.reshape(m, 3, 3)
        cov, lam_det = sym_inv_det(lam)
        cov = 0.5 * (cov + np.swapaxes(cov, -1, -2))
        shift = (cov @ eta[..., None])[..., 0]
        mode = x_hat + shift
        mode[:, 2] = wrap_angle(mode[:, 2])
        nis = quad - np.einsum("mi,mi->m", eta, shift)
        ll = -0.5 * (nis + logdet + np.log(p_det) + np.log(lam_det))
        return mode, cov, ll, nis, lam - lam0

    def _fold(
        self, x_hat: np.ndarray, mi: np.ndarray, bi: np.ndarray, z: np.ndarray, r: np.ndarray, rows: np.ndarray,
        prior_cov: np.ndarray, iterations: int,
    ) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray], tuple, np.ndarray, np.ndarray]:
        """The Gaussian proposal N(mode, Λ⁻¹) of the poses (M, 3) given the prior N(x̂, P) and
        the pairs (particle mi, observation bi of z (B, dim) and r, landmark at pool row rows),
        relinearised ``iterations`` times at the mode (iterated EKF: ν = z − ẑ(x_i) +
        Hₓ(x_i)(x_i − x̂)).

        Returns:
            ((mode (M, 3), Λ⁻¹ (M, 3, 3), log marginal likelihood (M,), νᵀS⁻¹ν (M,),
            observation information Σ HₓᵀZ⁻¹Hₓ (M, 3, 3)); the per-pair terms of the last
            linearisation (HₓᵀZ⁻¹Hₓ, HₓᵀZ⁻¹ν, νᵀZ⁻¹ν, dim·log 2π + log|Z|, ν, Z⁻¹, Hₓ; the last
            three possibly empty without ``association.outlier_gate``); P⁻¹ (M, 3, 3) and |P| (M,)).
        """
        lam0, p_det = sym_inv_det(prior_cov)
        x_lin = x_hat
        store = self.landmarks
        for it in range(iterations):
            dx = np.zeros(x_lin.shape)
            if it:
                dx = x_lin - x_hat
                dx[:, 2] = wrap_angle(dx[:, 2])
            terms = self.model.proposal_terms(
                x_lin, dx, z, r, mi, bi, store.field_rows("mean"), store.field_rows("cov"), rows,
                residuals=self.config.association.outlier_gate > 0,  # only _robust_fold reads them
            )
            fit = self._combine(x_hat, mi, terms, lam0, p_det)
            x_lin = fit[0]
        return fit, terms, lam0, p_det

    def _inform_drift(self, k: int, prior: np.ndarray, info: np.ndarray) -> None:
        """D ← (prior⁻¹ + info)⁻¹: robot k's drift covariance after a landmark update."""
        inv = np.linalg.inv(prior + 1e-12 * np.eye(3))
        d = np.linalg.inv(inv + info)
        self.drift_cov[k] = 0.5 * (d + d.T)

    def _drift(self, k: int) -> np.ndarray:
        d = self.drift_cov.get(k)
        if d is None:
            d = np.diag(np.square(np.asarray(self.config.initial_pose_sigma, float)))
            self.drift_cov[k] = d
        return d

    def _propagate_drift(self, k: int, odo: np.ndarray, dt: float) -> None:
        """D ← F D Fᵀ + Q for robot k's motion ``odo`` (EKF prediction at its mean pose)."""
        self.drift_cov[k] = self._propagate(self._drift(k), k, odo, dt)

    def _propagate(self, cov: np.ndarray, k: int, odo: np.ndarray, dt: float) -> np.ndarray:
        """F cov Fᵀ + Q: a pose covariance (3, 3, map frame) of robot k carried through its
        motion ``odo`` [m, m, rad] over dt [s], linearised at the weighted mean heading."""
        w = np.exp(self.log_w)
        th = float(np.arctan2(w @ np.sin(self.poses[:, k, 2]), w @ np.cos(self.poses[:, k, 2])))
        pose = np.array([[0.0, 0.0, th]])
        moved, q = predict_motion(pose, odo, self.config.motion, dt)
        f = np.eye(3)
        f[0, 2] = -moved[0, 1]  # ∂(x ⊕ δ)/∂θ = (−Δy, Δx) in the map frame
        f[1, 2] = moved[0, 0]
        return f @ cov @ f.T + q[0]

    def _draw_pending(self, k: int) -> None:
        """Sample robot k's accumulated motion noise into its poses (defer_motion_noise)."""
        cov = self.pending_cov.pop(k, None)
        if cov is None:
            return
        chol = np.linalg.cholesky(cov + 1e-12 * np.eye(3))
        self.poses[:, k] += self.rng.standard_normal((self.num_particles, 3)) @ chol.T
        self.poses[:, k, 2] = wrap_angle(self.poses[:, k, 2])

    def _descriptor_filter(self, cand: np.ndarray, desc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Keep the candidates whose descriptor distance E (eq. 16) is at most E0, nearest first.

        The association rule picks the gated candidate of least E and rejects it if E > E0, so a
        candidate above E0 can never be chosen; dropping it before the per-particle gate gives
        the same associations at a fraction of the cost. Returns (cand (B, C'), E (B, C')).
        """
        e0 = self.config.association.descriptor_gate
        valid = cand >= 0
        if desc.shape[1]:
            e = ((desc[:, None, :] - self.landmarks.descriptor[np.where(valid, cand, 0)]) ** 2).sum(-1)
        else:
            e = np.zeros(cand.shape)
        valid &= e <= e0
        order = np.argsort(np.where(valid, e, np.inf), axis=1, kind="stable")
        width = int(valid.sum(axis=1).max(initial=0))
        cand = np.where(valid, cand, -1)
        cand = np.take_along_axis(cand, order, 1)[:, :width]
        e = np.take_along_axis(e, order, 1)[:, :width]
        return cand, e

    def _update_existence(
        self, poses: np.ndarray, mean_pose: np.ndarray, radius: float, mi: np.ndarray, seen_slots: np.ndarray
    ) -> None:
        """Existence counters (001 III-F): landmarks in the footprint but not seen lose a point."""
        ex = self.config.existence
        store = self.landmarks
        center = np.zeros(store.dim)
        center[:2] = mean_pose[:2]
        reach = ex.max_range + radius + (3.0 if store.dim == 3 else 0.0)
        slots = store.within(center, reach)
        if slots.size == 0:
            return
        m = self.num_particles
        mean, held, score = store.gather(np.arange(m)[:, None], slots[None], ("mean", "exists", "score"))
        dx = mean[..., 0] - poses[:, None, 0]
        dy = mean[..., 1] - poses[:, None, 1]
        c, s = np.cos(poses[:, None, 2]), np.sin(poses[:, None, 2])
        xb, yb = c * dx + s * dy, -s * dx + c * dy
        rng = np.hypot(xb, yb)
        visible = held & (rng >= ex.min_range) & (rng <= ex.max_range)
        visible &= np.abs(np.arctan2(yb, xb)) <= ex.fov_rad / 2
        if mi.size:
            pos = np.searchsorted(slots, seen_slots)
            ok = (pos < slots.size) & (slots[np.minimum(pos, slots.size - 1)] == seen_slots)
            visible[mi[ok], pos[ok]] = False
        pm, ps = np.nonzero(visible)
        if pm.size == 0:
            return
        new_score = score[pm, ps] - 1
        store.write(pm, slots[ps], score=new_score, exists=new_score >= 0)
        self.removed_landmarks += int((new_score < 0).sum())

    def _create(
        self, poses: np.ndarray, z: np.ndarray, r: np.ndarray, desc: np.ndarray, tracks: np.ndarray,
        new: np.ndarray, stamp_ns: int, maker: int,
    ) -> tuple[int, np.ndarray]:
        """New landmarks for observations that were not associated: one slot per observation.

        Returns: the number of slots started, and (M, B) the slot each particle started for each
        observation (−1: none)."""
        store = self.landmarks
        cols = np.flatnonzero(new.any(axis=0))
        started = np.full(new.shape, -1, np.int64)
        if cols.size == 0:
            return 0, started
        slots = store.allocate(cols.size, desc[cols])
        store.origin[slots] = tracks[cols]
        store.born[slots] = stamp_ns
        store.maker[slots] = maker
        mi, j = np.nonzero(new[:, cols])
        bi = cols[j]
        lm, cov = self.model.new_landmark_rows(poses, z, r, mi, bi)
        store.write(mi, slots[j], mean=lm, cov=cov, exists=True, count=1, score=1)
        store.set_reference(slots[j], lm)
        started[mi, bi] = slots[j]
        return int(cols.size), started

    def _observe_robot(self, k: int, sighting: RobotSighting, log_l: np.ndarray) -> None:
        """Score a range-bearing sighting of another robot in every particle."""
        target = self.index.get(sighting.target)
        z = np.asarray(sighting.z, float)
        cov = np.asarray(sighting.cov, float)
        if target is None or target == k:
            self.dropped["bad_sighting"] += 1
            return
        if z.shape != (2,) or cov.shape != (2, 2) or not np.isfinite(z).all():
            self.dropped["bad_sighting"] += 1
            return
        if np.abs(z).max() > MAX_ABS_INPUT:
            self.dropped["bad_sighting"] += 1
            return
        if not is_positive_definite(cov) or not (
            (np.diag(cov) >= VARIANCE_BOUNDS[0]) & (np.diag(cov) <= VARIANCE_BOUNDS[1])
        ).all():
            self.dropped["bad_sighting"] += 1
            return
        if self.config.defer_motion_noise:
            log_l += self._sighting_marginal(k, target, z, cov, log_l)
            return
        self._draw_pending(k)
        self._draw_pending(target)
        rb = RangeBearingModel()
        zhat, _ = rb.predict(self.poses[:, k], self.poses[:, target, :2])
        nu = rb.innovation(z[None], zhat)
        inv, det = sym_inv_det(cov)
        log_l += self._robust_sighting(-0.5 * (quad_form(nu, inv[None]) + 2 * LOG_2PI + np.log(det)))[0]

    def _robust_sighting(self, ll_in: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(log-likelihood (M,), inlier probability (M,)) of a sighting whose Gaussian
        log-likelihood is ``ll_in``, under the outlier mixture (1 − ε)·N + ε·U with U uniform over
        range 0–10 m and bearing ±π (``sighting_outlier_probability`` ε)."""
        eps = self.config.sighting_outlier_probability
        if eps <= 0:
            return ll_in, np.ones_like(ll_in)
        ll = np.logaddexp(np.log1p(-eps) + ll_in, np.log(eps) - np.log(10.0 * 2 * np.pi))
        return ll, np.exp(np.log1p(-eps) + ll_in - ll)

    def _sighting_marginal(self, k: int, target: int, z: np.ndarray, cov: np.ndarray, log_l: np.ndarray) -> np.ndarray:
        """A sighting of robot ``target`` by robot ``k`` against their poses with the motion
        noise still pending (``defer_motion_noise``): each particle's two poses are Gaussians
        N(x, P) with the robots' pending covariances P. The sighting is scored by its marginal
        likelihood N(ν; 0, R + Σ H P Hᵀ), linearised at the particle's poses, and conditions
        each Gaussian (an EKF update of the means, weighted by the reading's inlier
        probability under ``sighting_outlier_probability``) instead of sampling the noise
        first: a sighting measures where a robot is, not where it heads, and a drawn heading
        that nothing selects would be kept or lost at the next resampling by chance.
        The pending covariances shrink by the posterior-weighted mean of K S Kᵀ; the
        correlation the sighting makes between the two robots is not kept.

        Returns:
            (M,) log-likelihood of the sighting per particle.
        """
        rb = RangeBearingModel()
        m = self.num_particles
        zhat, g = rb.predict(self.poses[:, k], self.poses[:, target, :2])
        nu = rb.innovation(z[None], zhat)
        jac = {k: rb.pose_jacobian(self.poses[:, k], self.poses[:, target, :2]),
               target: np.concatenate([g, np.zeros((m, 2, 1))], axis=2)}
        pending = {r: self.pending_cov[r] for r in (k, target) if r in self.pending_cov}
        s = np.broadcast_to(cov, (m, 2, 2)).copy()
        for r, p in pending.items():
            s += jac[r] @ p @ np.swapaxes(jac[r], 1, 2)
        inv, det = sym_inv_det(s)
        ll, inlier = self._robust_sighting(-0.5 * (quad_form(nu, inv) + 2 * LOG_2PI + np.log(det)))
        if not pending:  # both robots' noise already drawn: the reading only weighs
            return ll
        post = self.log_w + log_l + ll  # the particles' weights with this update's terms so far
        post = np.exp(post - post.max())
        post /= post.sum()
        for r, p in pending.items():
            gain = p @ np.swapaxes(jac[r], 1, 2) @ inv  # (M, 3, 2)
            self.poses[:, r] += inlier[:, None] * (gain @ nu[..., None])[..., 0]
            self.poses[:, r, 2] = wrap_angle(self.poses[:, r, 2])
            shrink = np.einsum("m,mij->ij", post * inlier, gain @ s @ np.swapaxes(gain, 1, 2))
            p = p - shrink
            self.pending_cov[r] = 0.5 * (p + p.T)
        return ll

    def _resample(self) -> None:
        index = low_variance_indices(self.log_w, self.rng)
        dst, src = copy_plan(index)
        self.poses[dst] = self.poses[src]
        self.score[dst] = self.score[src]
        self.landmarks.copy_rows(dst, src)
        for memory in self.tracks.values():
            memory.copy_rows(dst, src)
        if self.resamples % 8 == 0 and self.landmarks.dead_fraction() > 0.5:
            remap = self.landmarks.compact()
            for memory in self.tracks.values():
                memory.remap(remap)
        self.log_w = np.full(self.num_particles, -np.log(self.num_particles))
        self.resamples += 1

    # ------------------------------------------------------------------ robots joining (004, issue 8)
    def add_robot(
        self, name: str, poses: np.ndarray, stamp_ns: int | None = None,
        drift_cov: np.ndarray | None = None, pending_cov: np.ndarray | None = None,
    ) -> int:
        """Make ``name`` one more robot of the filter (a robot merged late, 004 section 5).

        Args:
            name: the robot; if it already is a robot of the filter (it restarted), its poses
                are replaced and its stamp history reset.
            poses: (M, 3) its pose in each particle, map frame (x [m], y [m], θ [rad]).
            stamp_ns: time of those poses (ns); its next update must be later. None: no history.
            drift_cov: (3, 3) its drift covariance (map frame, see :attr:`drift_cov`); None:
                the initial σ² of the config.
            pending_cov: (3, 3) motion noise accumulated but not yet sampled (map frame,
                ``defer_motion_noise``); None: none.

        Returns:
            the robot's index k on the K axis of :attr:`poses`.
        """
        poses = np.array(poses, dtype=float)
        if poses.shape != (self.num_particles, 3) or not np.isfinite(poses).all():
            raise FilterInputError(f"poses of {name!r} must be finite ({self.num_particles}, 3)")
        poses[:, 2] = wrap_angle(poses[:, 2])
        if name in self.index:
            k = self.index[name]
            self.poses[:, k] = poses
        else:
            k = len(self.robots)
            self.robots.append(name)
            self.index[name] = k
            self.poses = np.concatenate([self.poses, poses[:, None]], axis=1)
        self.last_stamp.pop(name, None)
        self.tracks.pop(k, None)
        if stamp_ns is not None:
            self.last_stamp[name] = int(stamp_ns)
        for store, cov in ((self.drift_cov, drift_cov), (self.pending_cov, pending_cov)):
            store.pop(k, None)
            if cov is not None:
                store[k] = 0.5 * (np.asarray(cov, float) + np.asarray(cov, float).T)
        return k

    def select_particles(self, index: np.ndarray, score: np.ndarray | None = None) -> None:
        """Particle n becomes a copy of particle ``index[n]`` (in that order); weights uniform.

        Poses and scores are copied by fancy indexing and landmark maps through the store's
        copy-on-write rows, so duplicated particles never share writable state.

        Args:
            index: (M,) ancestor of each particle.
            score: (M,) their summed log likelihoods (eq. 14) afterwards; default the ancestors'.
        """
        index = np.asarray(index, np.int64)
        m = self.num_particles
        if index.shape != (m,) or index.min(initial=0) < 0 or index.max(initial=0) >= m:
            raise FilterInputError(f"index must be ({m},) particle indices")
        self.poses = self.poses[index]
        self.score = self.score[index] if score is None else np.array(score, dtype=float)
        self.landmarks.copy_rows(np.arange(m), index)
        for memory in self.tracks.values():
            memory.slots = memory.slots[index]
        self.log_w = np.full(m, -np.log(m))

    def insert_landmarks(
        self, mean: np.ndarray, cov: np.ndarray, exists: np.ndarray, descriptors: np.ndarray,
        count: np.ndarray | None = None,
    ) -> np.ndarray:
        """Add N landmarks made elsewhere (another robot's map) to the particles that hold them.

        Args:
            mean: (M, N, dim) position in each particle, map frame [m].
            cov: (M, N, dim, dim) covariances [m²].
            exists: (M, N) bool, which particle holds which landmark.
            descriptors: (N, D) one descriptor per landmark.
            count: (M, N) observations behind each value (default 1).

        Returns:
            (N,) the new slots.
        """
        store = self.landmarks
        exists = np.asarray(exists, bool)
        m, n = exists.shape
        if m != self.num_particles or mean.shape != (m, n, store.dim) or cov.shape != (m, n, store.dim, store.dim):
            raise FilterInputError(f"landmarks must be ({self.num_particles}, N, {store.dim}[, {store.dim}])")
        slots = store.allocate(n, np.asarray(descriptors, np.float32).reshape(n, -1))
        mi, j = np.nonzero(exists)
        if mi.size:
            cnt = np.ones(mi.size, np.int64) if count is None else np.asarray(count)[mi, j]
            store.write(
                mi, slots[j], mean=mean[mi, j], cov=cov[mi, j], exists=True, count=cnt,
                score=np.minimum(cnt, self.config.existence.max_score),
            )
            store.set_reference(slots[j], mean[mi, j])
        return slots
