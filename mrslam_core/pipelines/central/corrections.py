"""Corrections: moving a robot of the central filter where its odometry alone would not put it.

One decision serves both occasions: a robot back from a gap (silent for longer than
``relocalize_after``), and every ``map_check.every`` seconds each robot, is aligned to the older
map, and whether it is where its filter says or lost is decided in every particle by the
posterior odds of the two (:mod:`~mrslam_core.pipelines.central.map_move`); a lost robot takes a
pose drawn from the alignment in the particles that find it lost, and the landmarks it made from
the poses the check found off are dropped (:meth:`Corrections._drop_window_landmarks`). The
motion over a long gap (``sample_gap``) is sampled before the set is associated. The mapper
calls these at fixed points of an update (:meth:`Corrections.before_step`,
:meth:`Corrections.hold`, :meth:`Corrections.after_step`, :meth:`Corrections.forget`).
"""

from __future__ import annotations

from collections import Counter, deque
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from mrslam_core.geometry.se2 import between, compose, pose_moments, wrap_angle
from mrslam_core.pipelines.central.config import CentralConfig
from mrslam_core.pipelines.central.map_move import (MoveResult, candidate_pairs, frame_log_likelihood, lost_or_not,
                                                   refine)
from mrslam_core.pipelines.central.ordering import Pairing
from mrslam_core.pipelines.central.state import set_from_state, sets_state
from mrslam_core.slam.filter import FilterInputError, MultiRobotFastSLAM, RobotUpdate
from mrslam_core.types import ObservationSet

#: χ²(3 dof) at 0.99: the frame's refit near the estimate counts as the mode of "where the filter
#: says" only within this Mahalanobis distance of the estimate under P + Σ_T (a refit that slid
#: further, along a repetitive wall, is a mode of "lost", and the alignment stands for those)
LOCAL_GATE = 11.34


class Corrections:
    """The placement after a gap, the gap sampling and the map check, and what they remember.

    Args:
        cfg: ``relocalize_*``, ``sample_gap``, ``map_check``, ``fusion`` and the filter's
            ``observation_model`` apply.
        robots: robot names.
        drops: the mapper's drop counter (by reason), counted into.

    Raises:
        ValueError: the gap re-localisation (``relocalize_after``) or the map check
            (``map_check.every``) on with a filter whose observations are not 3D points (they
            align stereo points; a profile of another sensor switches them off, as
            config/mrclam.yaml does).

    Attributes:
        relocalizations: every re-localisation after a gap (cause "gap": robot, stamp_ns, gap_s,
            travelled_m, accepted (an alignment was weighed), reason, inliers, shift_m (the fit
            from the dead-reckoned pose), lost (share of particles that found the robot lost and
            moved it), p_lost (mean posterior probability of lost)) and every move by a map check
            (cause "map_check": the robot lost in most particles; also turn_rad, transform).
        map_checks: map checks made, by outcome: too_few_points, no_fit (no alignment),
            agreed (the robot is where its filter says in most particles), moved.
        distrusted: (robot index, from_ns, to_ns): landmarks that robot made in that time, left
            out of map checks (``map_check.distrust_moved``).
    """

    def __init__(self, cfg: CentralConfig, robots: list[str], drops: Counter[str]):
        if cfg.filter.observation_model != "stereo_point" and (cfg.relocalize_after > 0 or cfg.map_check.every > 0):
            raise ValueError(f"relocalize_after and map_check.every align stereo points: set both to 0 with "
                             f"filter.observation_model {cfg.filter.observation_model}")
        self.cfg = cfg
        self.robots = robots
        self.drops = drops
        self.relocalizations: list[dict] = []
        self.map_checks: Counter[str] = Counter()
        self.distrusted: list[tuple[int, int, int]] = []
        #: robots back from a gap, not re-localised yet: (attempts left, stamp the gap began [ns])
        self._returning: dict[str, tuple[int, int]] = {}
        #: stamp of each robot's last re-localisation attempt [ns]
        self._reloc_tried: dict[str, int] = {}
        #: each robot's recent sets for the map check: (stamp_ns, pose (3,) per map_check.poses, set)
        self._recent: dict[str, deque[tuple[int, np.ndarray, ObservationSet]]] = {r: deque() for r in robots}
        #: stamp of each robot's last map check [ns]
        self._checked: dict[str, int] = {}
        #: each robot's last agreeing map check [ns]
        self._agreed: dict[str, int] = {}
        #: each robot's last map check that moved it in no particle [ns]
        self._unmoved: dict[str, int] = {}

    # ------------------------------------------------------------------ the mapper's calls
    def before_step(self, slam: MultiRobotFastSLAM, filt: MultiRobotFastSLAM, obs: ObservationSet,
                    pairing: Pairing, path_length: Callable[[str, int, int], float]) -> np.ndarray:
        """Before ``filt`` (the central filter ``slam`` or the robot's local one) takes ``obs``:
        re-localise a robot back from a gap, sample the motion over a long one. Returns the
        motion (3,) [m, rad, robot frame] still to apply with the set.

        Args:
            pairing: the set's odometry.
            path_length: distance (robot, from_ns, to_ns) -> [m] the robot's odometry covered.
        """
        motion = between(pairing.reference, pairing.odom)
        motion = self._relocalize_if_back(slam, filt, obs, pairing.previous_ns, motion, path_length)
        return self._sample_gap(filt, obs, pairing, motion)

    def hold(self, obs: ObservationSet) -> bool:
        """True if ``obs``'s robot awaits its re-localisation: its pose is in doubt, so the set
        moves it by odometry only and must not shape the map (counted)."""
        if obs.robot in self._returning:
            self.drops["awaiting_relocalization"] += 1
            return True
        return False

    def after_step(self, slam: MultiRobotFastSLAM, obs: ObservationSet, odom: np.ndarray) -> None:
        """After the central filter ``slam`` mapped ``obs`` (taken at odometry pose ``odom`` (3,)):
        the map check."""
        self._check_map(slam, obs, odom)

    def forget(self, robot: str) -> None:
        """Drop what is remembered of ``robot`` (its odometry restarted: it is mapped anew)."""
        for state in (self._returning, self._reloc_tried, self._checked, self._agreed, self._unmoved):
            state.pop(robot, None)
        self._recent[robot].clear()

    # ------------------------------------------------------------------ gaps
    def _relocalize_if_back(self, slam: MultiRobotFastSLAM, filt: MultiRobotFastSLAM, obs: ObservationSet,
                            previous_ns: int | None, motion: np.ndarray,
                            path_length: Callable[[str, int, int], float]) -> np.ndarray:
        """Try to place a central robot whose previous update is older than
        ``relocalize_after``, at most once a second and ``relocalize_tries`` times; the motion
        (3,) left to apply: none once placed."""
        cfg = self.cfg
        if obs.robot in self._returning:
            seen = self._returning[obs.robot][1]
        elif previous_ns is None:
            seen = obs.stamp_ns
        else:
            seen = previous_ns
        gap = (obs.stamp_ns - seen) * 1e-9
        tried = self._reloc_tried.get(obs.robot, seen)
        relocalizing = filt is slam and 0 < cfg.relocalize_after < gap
        if relocalizing and len(obs) < cfg.fusion.min_inliers and obs.robot not in self._returning:
            # back from silence with too few points to place it (a frontend's tracks start again
            # after a gap): the gap stays open until a set can be aligned, and its sets wait
            self._returning[obs.robot] = (cfg.relocalize_tries, seen)
        if relocalizing and obs.stamp_ns - tried >= 1e9 and len(obs) >= cfg.fusion.min_inliers:
            self._reloc_tried[obs.robot] = obs.stamp_ns
            left = self._returning.get(obs.robot, (cfg.relocalize_tries, seen))[0] - 1
            if self._relocalize(slam, obs, motion, gap, path_length(obs.robot, seen, obs.stamp_ns)):
                motion = np.zeros(3)  # the particles are at this stamp already
                left = 0
            if left > 0:
                self._returning[obs.robot] = (left, seen)  # the gap stays open: try again a second later
            else:
                self._returning.pop(obs.robot, None)
        return motion

    def _sample_gap(self, filt: MultiRobotFastSLAM, obs: ObservationSet, pairing: Pairing,
                    motion: np.ndarray) -> np.ndarray:
        """Over a gap longer than ``sample_gap``, apply the motion up to 0.2 s before the set
        without observations first; the motion (3,) left to apply with the set."""
        prev = pairing.previous_ns
        if prev is not None and 0 < self.cfg.sample_gap < (obs.stamp_ns - prev) * 1e-9 and motion.any():
            mid_ns = obs.stamp_ns - 200_000_000
            mid = pairing.at(mid_ns)
            if mid is None:
                mid = pairing.reference
            try:
                filt.step([RobotUpdate(obs.robot, mid_ns, between(pairing.reference, mid), None)])
                motion = between(mid, pairing.odom)
            except FilterInputError:
                pass
        return motion

    def _relocalize(self, slam: MultiRobotFastSLAM, obs: ObservationSet, motion: np.ndarray, gap: float,
                    travelled: float) -> bool:
        """Place ``obs.robot``, back after ``gap`` s and ``travelled`` m, by aligning its
        observation set (base_link) to the best particle's map; True if its particles were
        redrawn (logged in :attr:`relocalizations` either way)."""
        from mrslam_core.fusion.alignment import ransac_align
        from mrslam_core.fusion.maps import FusionError, LandmarkMap

        k = slam.index[obs.robot]
        dead = compose(slam.estimate().mean[k], motion)
        entry = {"robot": obs.robot, "stamp_ns": int(obs.stamp_ns), "cause": "gap", "gap_s": gap,
                 "travelled_m": travelled, "accepted": False}
        self.relocalizations.append(entry)
        limit = self.cfg.relocalize_gate + self.cfg.relocalize_drift * travelled
        try:
            frame = LandmarkMap(obs.z, obs.cov, obs.descriptors)
            world = self.map_near(slam, dead, obs.z, limit)
            al = ransac_align(world, frame, self.cfg.fusion)
        except FusionError as exc:
            entry["reason"] = str(exc)
            return False
        entry.update(reason=al.reason, inliers=int(len(al.inliers)))
        if not al.accepted:
            return False
        entry["shift_m"] = float(np.hypot(*(al.transform[:2] - dead[:2])))
        # where the odometry puts it over the gap, in each particle, against lost within the gate
        placed = compose(slam.poses[:, k], motion)
        sigma_xy = self.cfg.map_check.sigma_xy + self.cfg.relocalize_drift * travelled
        res = self._decide(slam, k, placed, frame, world, al, sigma_xy, limit)
        entry.update(lost=float(res.lost.mean()), p_lost=float(res.p_lost.mean()))
        slam.add_robot(obs.robot, res.poses)
        entry["accepted"] = True
        return True

    # ------------------------------------------------------------------ the map check
    def _check_map(self, slam: MultiRobotFastSLAM, obs: ObservationSet, odom: np.ndarray) -> None:
        """Keep ``obs`` (taken at odometry pose ``odom``) among its robot's recent sets and, when
        due, align those sets to the older map and move the robot if the map disagrees
        (:class:`MapCheckConfig`)."""
        mc = self.cfg.map_check
        if mc.every <= 0:
            return
        k = slam.index[obs.robot]
        est = slam.estimate().mean[k]
        at = est if mc.poses == "estimate" else odom
        recent = self._recent[obs.robot]
        if len(obs):
            recent.append((int(obs.stamp_ns), at, obs))
        while recent and recent[0][0] < obs.stamp_ns - mc.window * 1e9:
            recent.popleft()
        if obs.stamp_ns - self._checked.get(obs.robot, -(1 << 62)) < mc.every * 1e9:
            return
        self._checked[obs.robot] = int(obs.stamp_ns)
        from mrslam_core.fusion.alignment import ransac_align
        from mrslam_core.fusion.maps import FusionError

        frame = self._recent_frame(obs.robot, at)
        if frame is None or len(frame.means) < mc.min_inliers:
            self.map_checks["too_few_points"] += 1
            return
        world = self.map_near(slam, est, frame.means, mc.max_shift, obs.stamp_ns - mc.age * 1e9)
        try:
            al = ransac_align(world, frame, replace(self.cfg.fusion, min_inliers=mc.min_inliers))
        except FusionError:
            al = None
        if al is None or not al.accepted:
            self.map_checks["no_fit"] += 1
            return
        res = self._decide(slam, k, slam.poses[:, k].copy(), frame, world, al, mc.sigma_xy, mc.max_shift)
        moved = res.lost.mean() > 0.5
        if not moved:
            self.map_checks["agreed"] += 1
            self._agreed[obs.robot] = int(obs.stamp_ns)
        else:
            self.map_checks["moved"] += 1
            if mc.distrust_moved:
                self.distrusted.append((k, self._agreed.get(obs.robot, -1), int(obs.stamp_ns)))
            self.relocalizations.append({
                "robot": obs.robot, "stamp_ns": int(obs.stamp_ns), "cause": "map_check", "accepted": True,
                "reason": "", "inliers": int(len(al.inliers)), "lost": float(res.lost.mean()),
                "p_lost": float(res.p_lost.mean()), "shift_m": float(np.hypot(*(al.transform[:2] - est[:2]))),
                "turn_rad": float(wrap_angle(al.transform[2] - est[2])),
                "transform": [float(v) for v in al.transform]})
        if res.lost.any():
            # the sets the check weighed, after the last check that confirmed the robot in every
            # particle: the ones the alignment says were placed off. Where most particles moved
            # it, in every particle: a particle left in the lost frame keeps its landmarks of that
            # frame and explains the next sets better than the moved ones, whose landmarks there
            # are gone, and resampling would pick it
            since = max(int(obs.stamp_ns - mc.window * 1e9), self._unmoved.get(obs.robot, -1))
            self._drop_window_landmarks(slam, k, np.ones_like(res.lost) if moved else res.lost, since)
            slam.poses[:, k] = res.poses
        else:
            self._unmoved[obs.robot] = int(obs.stamp_ns)
        if moved:
            slam.tracks.pop(k, None)  # its tracks went to landmarks seen from the old poses
            if mc.poses == "estimate":  # the recent sets were placed by the poses just replaced
                self._recent[obs.robot].clear()

    @staticmethod
    def _drop_window_landmarks(slam: MultiRobotFastSLAM, k: int, where: np.ndarray, since_ns: int) -> None:
        """In the particles ``where`` (M,) bool, drop the landmarks robot k created since
        ``since_ns`` [ns].

        They were placed from the poses the check found off. Left in the map, the robot meets
        them at once from its new pose and the filter's own update (they are the nearest,
        freshest landmarks) draws it back into the frame it was lost in; the robot maps the
        place again from the new pose. Dropped rather than moved with the robot: a move that a
        look-alike caused, and a later check undoes, then leaves no landmark displaced."""
        store = slam.landmarks
        slots = np.flatnonzero((store.maker[: store.size] == k) & (store.born[: store.size] >= since_ns))
        m = np.flatnonzero(where)
        if slots.size == 0 or m.size == 0:
            return
        (held,) = store.gather(m[:, None], slots[None, :], ("exists",))
        mi, si = np.nonzero(held)
        store.write(m[mi], slots[si], exists=False)
        store.refresh_reference(slots)

    def map_near(self, slam: MultiRobotFastSLAM, pose: np.ndarray, points: np.ndarray, margin: float,
                 born_before: float | None = None):
        """The best particle's landmarks (a :class:`LandmarkMap`, map frame) that ``points`` (N, ≥2),
        seen from base_link, can be matched to from anywhere within ``margin`` [m] of ``pose`` (3,):
        fewer look-alikes; with ``born_before``, only those created before that stamp [ns]."""
        from mrslam_core.fusion.maps import LandmarkMap

        world = LandmarkMap.from_filter(slam)
        reach = margin + float(np.linalg.norm(points[:, :2], axis=1).max()) + self.cfg.fusion.inlier_distance
        keep = np.linalg.norm(world.means[:, :2] - pose[:2], axis=1) <= reach
        if born_before is not None:
            keep &= slam.landmarks.born[world.ids] < born_before
        if self.distrusted:
            maker, born = slam.landmarks.maker[world.ids], slam.landmarks.born[world.ids]
            for k, t0, t1 in self.distrusted:
                keep &= ~((maker == k) & (born >= t0) & (born <= t1))
        return world.subset(np.flatnonzero(keep))

    def _decide(self, slam: MultiRobotFastSLAM, k: int, poses: np.ndarray, frame, world, al,
                sigma_xy: float, max_shift: float) -> MoveResult:
        """Robot k at ``poses`` (M, 3) or lost within ``max_shift`` [m]: the decision of
        :func:`~.map_move.lost_or_not` for ``frame`` (its base_link) against ``world`` (the
        older map, best particle's rows; each particle's own landmarks are read at those slots),
        with the alignment ``al`` as the lost robot's proposal and ``sigma_xy`` [m] added to the
        spread of its particles."""
        mc, fusion = self.cfg.map_check, self.cfg.fusion
        pairs = candidate_pairs(world.descriptors, frame.descriptors, fusion.descriptor_threshold, mc.candidates)
        m = slam.num_particles
        mean, cov, held = slam.landmarks.gather(np.arange(m)[:, None], world.ids[pairs[:, 0]][None],
                                                ("mean", "cov", "exists"))
        reach = max_shift + float(np.linalg.norm(frame.means[:, :2], axis=1).max()) + fusion.inlier_distance
        log_area = float(np.log(np.pi * reach**2))

        def log_lik(x: np.ndarray) -> np.ndarray:
            return frame_log_likelihood(x, frame.means, frame.covs, pairs, mean, cov, held,
                                        mc.outlier_probability, log_area, mc.sigma_xy)

        centre, spread = pose_moments(poses, np.exp(slam.log_w))
        spread = spread + np.diag([sigma_xy**2, sigma_xy**2, mc.sigma_theta**2])
        fit_cov = np.nan_to_num(al.cov) + np.diag([mc.sigma_xy**2, mc.sigma_xy**2, mc.sigma_theta**2])
        fit_cov = 0.5 * (fit_cov + fit_cov.T)
        local = refine(centre, frame.means[:, :2], world.means[:, :2], pairs, fusion.inlier_distance)
        if local is not None:  # the mode of "where the filter says" lies within that hypothesis's prior
            d = local - centre
            d[2] = wrap_angle(d[2])
            if d @ np.linalg.solve(spread + fit_cov, d) > LOCAL_GATE:
                local = None
        return lost_or_not(poses, spread, al.transform, fit_cov, log_lik, mc.lost_probability,
                           max_shift, mc.max_turn, slam.rng, local)

    def _recent_frame(self, robot: str, pose: np.ndarray):
        """The robot's recent sets as one :class:`LandmarkMap` in its base_link at ``pose`` (3,)
        (estimate or odometry, as the sets were kept: ``map_check.poses``), newest observation of
        each frontend track only; None without points."""
        from mrslam_core.fusion.maps import FusionError, LandmarkMap

        parts, seen = [], set()
        for _, at, o in reversed(self._recent[robot]):
            fresh = np.array([t < 0 or t not in seen for t in o.track_ids.tolist()], bool)
            seen.update(o.track_ids[fresh & (o.track_ids >= 0)].tolist())
            if fresh.any():
                try:
                    parts.append(LandmarkMap(o.z[fresh], o.cov[fresh], o.descriptors[fresh]).transformed(between(pose, at)))
                except FusionError:
                    continue
        if not parts:
            return None
        return LandmarkMap(np.concatenate([p.means for p in parts]), np.concatenate([p.covs for p in parts]),
                           np.concatenate([p.descriptors for p in parts]))

    # ------------------------------------------------------------------ checkpoint
    def state(self) -> dict[str, Any]:
        """Everything above as JSON values and arrays: ``relocalizations``, ``map_checks``,
        ``distrusted``, ``returning`` (robot: [attempts left, gap start ns]),
        ``reloc_tried``, ``checked``, ``agreed``, ``unmoved``, ``recent`` ([robot, stamp_ns, pose
        (3)] in each robot's order) with the sets' arrays (``recent_*_{i}``)."""
        recent = [(r, s, at, o) for r in self.robots for s, at, o in self._recent[r]]
        return {
            "relocalizations": [dict(e) for e in self.relocalizations], "map_checks": dict(self.map_checks),
            "distrusted": [list(d) for d in self.distrusted],
            "returning": {r: list(v) for r, v in self._returning.items()}, "reloc_tried": dict(self._reloc_tried),
            "checked": dict(self._checked), "agreed": dict(self._agreed), "unmoved": dict(self._unmoved),
            "recent": [[r, s, *map(float, at)] for r, s, at, _ in recent],
            **sets_state("recent", [o for *_, o in recent]),
        }

    def load_state(self, state: dict[str, Any]) -> None:
        """Take the state :meth:`state` gave (into a new part, of the same robots); keys a version
        2 checkpoint lacks keep their initial values."""
        self.relocalizations = [dict(e) for e in state.get("relocalizations", [])]
        self.map_checks = Counter(state.get("map_checks", {}))
        self.distrusted = [tuple(int(x) for x in d) for d in state.get("distrusted", [])]
        self._returning = {r: (int(v[0]), int(v[1])) for r, v in state.get("returning", {}).items()}
        self._reloc_tried = {r: int(v) for r, v in state.get("reloc_tried", {}).items()}
        self._checked = {r: int(v) for r, v in state.get("checked", {}).items()}
        self._agreed = {r: int(v) for r, v in state.get("agreed", {}).items()}
        self._unmoved = {r: int(v) for r, v in state.get("unmoved", {}).items()}
        for i, (robot, stamp, *at) in enumerate(state.get("recent", [])):
            obs = set_from_state(state, "recent", i, robot, stamp)
            self._recent[robot].append((int(stamp), np.array(at, float), obs))
