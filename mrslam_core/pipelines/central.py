"""The central mapper: every robot's odometry and observation sets, in stamp order, into ONE filter.

This is what the central SLAM node does between its subscriptions and its publishers, without ROS,
so that a live graph, a bag replayed in real time and a bag fed offline make the same filter
steps in the same order (and, with the same seed, the same estimates).

Ordering: observation sets wait in a queue and are released in stamp order once every *active*
robot (every robot of the config, unless silent for ``max_wait`` before the newest observation
stamp, or never heard from within ``max_wait`` of the team's first set) has delivered a set at
least as new, or once the set is ``max_wait`` older than the newest observation stamp (a late or
silent robot delays the team by at most ``max_wait``; odometry does not advance this clock, so
frontends that lag behind the odometry do not reorder anything). A released set is paired with the robot's odometry
interpolated at its stamp; the motion since the robot's previous update is the filter's
odometry input. Everything that cannot be used is counted in :attr:`CentralMapper.drops`.
"""

from __future__ import annotations

import heapq
import time
from pathlib import Path
from collections import Counter, deque
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from mrslam_core.evaluation.metrics import interpolate_poses
from mrslam_core.fusion.config import FusionConfig
from mrslam_core.geometry.se2 import between, compose, transform_points, wrap_angle
from mrslam_core.slam.config import FilterConfig
from mrslam_core.slam.filter import FilterInputError, MultiRobotFastSLAM, RobotUpdate
from mrslam_core.types import ObservationSet


#: translation [m] and rotation [rad] an odometry pose may jump beyond odom_reset_speed and
#: odom_reset_turn_rate times the time since the previous pose (stamp jitter, message bursts)
ODOM_RESET_FLOOR = (0.1, 0.2)


@dataclass(frozen=True)
class MapCheckConfig:
    """Checking each robot against the older map while it drives (a robot that lost its heading).

    Every ``every`` seconds of a robot's sets, its sets of the last ``window`` seconds, moved into
    its current base_link (one point per frontend track), are aligned to the best
    particle's landmarks that are older than ``age`` (descriptor matches, RANSAC and least
    squares, the ``fusion`` thresholds but ``min_inliers``). Landmarks the robot mapped since it
    went wrong are younger and left out, so the fit shows where the older map puts the robot. If
    the fit is more than ``shift`` or ``turn`` away from the robot's estimate (and within
    ``max_shift`` and ``max_turn``: no jump across the building), the robot's pose is drawn again in
    every particle from the fit. A robot whose wheels slipped while it saw nothing comes back
    several degrees off, and then maps a corridor mapped before as a new one, turned: no
    association gate reaches landmarks 0.3 m away, while descriptors do.

    Attributes:
        every: seconds of a robot's sets between checks; 0: off [s].
        window: seconds of the robot's recent sets aligned together [s]. 3 s, not 2: after a
            blind turn a robot meets few old landmarks a set, and a longer window gathers the
            inliers a fit needs (closed loop, seeds 14-39: robots above 0.10 m 2 -> 1 of 78,
            docs/results.md).
        age: only landmarks created at least this long before the check take part [s].
        min_inliers: fewest RANSAC inliers of a fit that may move the robot.
        min_gain: a fit that disagrees must explain at least this many more of the window's
            descriptor matches (counted as ``gain_gate`` says) than the robot's estimate does;
            otherwise the two are look-alikes of each other and the check is ``ambiguous``.
            Recorded demos d1–d3 (counted within 0.3 m): moves that fixed a heading gained 9–35
            inliers; a move onto a fit 16° off gained 1, one onto a fit 0.8 m off gained 7.
        shift: a fit closer than this to the estimate, and within ``turn``, agrees with it [m].
        turn: see ``shift`` [rad]. 2.5°: under ``gain_gate`` an estimate 2.5–5° off explains
            far fewer matches than its fit and is corrected (counted within 0.3 m it explained
            about as many, and 2.5° moved no robot more than 5° did; docs/results.md).
        max_shift: a fit further than this from the estimate is not used [m].
        max_turn: a fit turned more than this from the estimate is not used [rad].
        sigma_xy: standard deviation added to the fit's own, per axis, when the poses are drawn [m].
        sigma_theta: the same for the heading [rad].
        gain_gate: how ``min_gain`` counts the matches a pose explains: 0, within the fusion's
            ``inlier_distance`` (the fit's RANSAC inliers against the estimate's); > 0, within
            this chi-square (2 dof) gate of the planar Mahalanobis distance under both points'
            covariances plus ``sigma_xy`` (the fit's and the estimate's counted alike). 9.21
            (chi-square 0.99): a robot 5° off explains no stereo point 2 m away, which a 0.3 m
            distance still counts (recorded demo d1, robot3 5.3° off: within 0.3 m its estimate
            explained 10 matches against the fit's 18, under the gate 1 against 21).
        distrust_moved: when a check moves a robot, the landmarks it made since its last
            agreeing check (all of them, if it never had one) were mapped from the wrong pose;
            later checks leave them out of the older map, so no robot is moved onto them.
        poses: what moves the window's sets into the current base_link: ``estimate``, the
            robot's filtered poses (their 2 s heading change errs 0.1–0.2° at the median, 1–5° at
            p95 in recorded runs; a robot that lost its heading still tracks its own new
            landmarks), or ``odometry`` (1–2.4° median, 5–8° p95 over 2 s in the same runs).
    """

    every: float = 1.0
    window: float = 3.0
    age: float = 10.0
    min_inliers: int = 10
    min_gain: int = 8
    shift: float = 0.3
    turn: float = 0.044
    max_shift: float = 1.0
    max_turn: float = 0.5
    sigma_xy: float = 0.03
    sigma_theta: float = 0.015
    poses: Literal["estimate", "odometry"] = "estimate"
    gain_gate: float = 9.21
    distrust_moved: bool = True


@dataclass(frozen=True)
class CentralConfig:
    """The central mapper.

    Attributes:
        robots: robot names (topic namespaces and frame prefixes), the K axis of the filter.
        start_poses: known start poses, x y θ per robot in ``robots`` order (map frame) [m, rad].
        odom_buffer: odometry poses kept per robot for interpolation.
        max_wait: longest a set waits for the other robots' sets of the same time [s].
        max_queue: observation sets held at most; beyond it the oldest is dropped and counted.
        unknown_start: robots whose start pose is unknown (their ``start_poses`` entries are not
            used); if every robot is listed, the first one's start pose defines the map frame.
        merge_every: updates of a robot with an unknown start between attempts to align its map.
        sample_gap: when a robot's previous update is older than this, its motion up to 0.2 s
            before the set is applied first without observations (each particle draws its own
            motion noise), then the rest with the set: the particles then associate the set
            from distinct poses, where a FastSLAM 2.0 proposal from the one predicted pose of a
            long motion follows whatever the set matches there (a restart of the central node,
            a frame dropped by a slow frontend); 0: never [s].
        relocalize_after: a robot whose previous update is older than this (it went silent:
            a link down, a frontend restarted) is placed by its observations instead of by its
            odometry over the gap: its observation set is aligned to the best particle's map
            (descriptor matches, RANSAC and least squares, ``fusion`` thresholds) and its
            particles drawn from the fit (stereo points only); 0: never [s].
        relocalize_when_blind: the gap of ``relocalize_after`` also runs while the robot's sets
            hold fewer than ``fusion.min_inliers`` points (blind: facing a wall, turning): it moved
            by odometry alone as much as a silent robot does.
        relocalize_tries: attempts, one a second, before a robot back from a gap is left to
            its odometry (a frame whose matches are bunched up cannot fix the rotation); its
            sets in between move it by odometry only and are counted, not mapped.
        relocalize_gate: the fit is used only within this distance of the dead-reckoned pose,
            plus ``relocalize_drift`` times the distance driven during the gap [m].
        relocalize_drift: see ``relocalize_gate`` [m/m].
        max_odom_gap: a set whose stamp falls between two odometry poses further apart than this
            is dropped (counted as ``odometry_gap``) instead of placed by interpolating across
            the hole (odometry lost while the central node was down, a driver that stalled); a
            robot turning at 0.5 rad/s at 0.35 m/s leaves a chord up to 2 cm off its arc over
            1 s, 9 cm over 2 s [s].
        odom_reset_speed: an odometry pose further from the robot's previous one than
            ``ODOM_RESET_FLOOR`` plus this speed times the time between them is an odometry
            reset (the robot's driver restarted, its odom frame is new; a robot carried while
            off): the robot is mapped on its own again from its new odometry origin and merged
            back by map alignment, as a robot with an unknown start (004 section 5); set it
            above the fastest robot of the team; 0: never [m/s].
        odom_reset_turn_rate: the same for the heading [rad/s].
        teammate_radius: stereo points within this horizontal distance of another robot's
            estimated position (base_link), and lower than ``teammate_height``, are that robot's
            body, not landmarks: they are left out of the set and counted (``on_teammate``, in
            points). Robots see each other; mapped as landmarks, a teammate's corners would move
            away with it and pull whoever associates them. Covers the body and the pose's
            uncertainty (a P3-DX's rear corner is 0.33 m from the axle); 0: off [m].
        teammate_height: top of the robots' bodies and sensor heads above the floor [m].
        map_check: checking each robot against the older map while it drives.
        filter: the multi-robot filter (and each unknown-start robot's local filter).
        fusion: map alignment and joining of unknown-start robots.
    """

    robots: tuple[str, ...] = ("robot1",)
    start_poses: tuple[float, ...] = (0.0, 0.0, 0.0)
    odom_buffer: int = 2000
    max_wait: float = 1.0
    max_queue: int = 200
    unknown_start: tuple[str, ...] = ()
    merge_every: int = 10
    sample_gap: float = 1.0
    relocalize_after: float = 5.0
    relocalize_when_blind: bool = False
    relocalize_tries: int = 3
    relocalize_gate: float = 0.5
    relocalize_drift: float = 0.1
    max_odom_gap: float = 1.0
    odom_reset_speed: float = 2.0
    odom_reset_turn_rate: float = 6.0
    teammate_radius: float = 0.0
    teammate_height: float = 0.6
    map_check: MapCheckConfig = field(default_factory=MapCheckConfig)
    filter: FilterConfig = field(default_factory=FilterConfig)
    fusion: FusionConfig = field(default_factory=FusionConfig)


@dataclass(frozen=True)
class Processed:
    """One filter update the mapper made.

    Attributes:
        robot: whose update.
        stamp_ns: its stamp [ns].
        pose: (3,) the robot's weighted-mean pose after the update, map frame.
        cov: (3, 3) its covariance.
        odom: (3,) the robot's odometry pose at the stamp, odom frame.
        step_ms: wall time of the filter step [ms].
        merged: the pose is in the map frame (False: an unknown-start robot not merged yet,
            whose pose is in its own start frame, or a robot back from silence awaiting its
            re-localisation, at its dead-reckoned pose).
    """

    robot: str
    stamp_ns: int
    pose: np.ndarray
    cov: np.ndarray
    odom: np.ndarray
    step_ms: float
    merged: bool = True


class CentralMapper:
    """Queue, order and pair the team's messages; run the filter; keep the trajectories.

    Args:
        cfg: robots, start poses, buffer sizes and the filter.
    """

    def __init__(self, cfg: CentralConfig):
        robots = list(cfg.robots)
        starts = np.asarray(cfg.start_poses, float)
        if starts.size != 3 * len(robots):
            raise ValueError(f"start_poses has {starts.size} numbers; {len(robots)} robots need {3 * len(robots)}")
        unknown = [r for r in cfg.unknown_start if r in robots]
        if set(cfg.unknown_start) - set(robots):
            raise ValueError(f"unknown_start names robots not in robots: {sorted(set(cfg.unknown_start) - set(robots))}")
        if len(unknown) == len(robots):
            unknown = unknown[1:]  # the first robot anchors the map frame
        self.cfg = cfg
        self.robots = robots
        known = [r for r in robots if r not in unknown]
        starts = starts.reshape(len(robots), 3)
        self.slam = MultiRobotFastSLAM(cfg.filter, known, starts[[robots.index(r) for r in known]])
        #: unknown-start (or restarted) robots not merged yet: their local filters (K = 1, own start frame)
        self.local = {r: self._local_filter(r) for r in unknown}
        self._local_updates: Counter[str] = Counter()
        #: every alignment attempt: robot, stamp_ns, accepted, reason, inliers, rmse_m, transform
        self.merges: list[dict] = []
        #: every re-localisation after a gap (cause "gap": robot, stamp_ns, gap_s, accepted, reason,
        #: inliers, shift_m) and every move by a map check (cause "map_check": also turn_rad)
        self.relocalizations: list[dict] = []
        #: map checks made, by outcome (see :class:`MapCheckConfig`)
        self.map_checks: Counter[str] = Counter()
        #: each robot's recent sets for the map check: (stamp_ns, pose (3,) per map_check.poses, set)
        self._recent: dict[str, deque[tuple[int, np.ndarray, ObservationSet]]] = {r: deque() for r in robots}
        self._checked: dict[str, int] = {}
        #: each robot's last disagreeing fit, waiting for the next check: (stamp_ns, pose, fit (3,))
        self._pending: dict[str, tuple[int, np.ndarray, np.ndarray]] = {}
        #: each robot's last agreeing map check [ns]
        self._agreed: dict[str, int] = {}
        #: (robot index, from_ns, to_ns): landmarks that robot made in that time, left out of map
        #: checks (``map_check.distrust_moved``)
        self._distrusted: list[tuple[int, int, int]] = []
        #: every odometry reset (a restarted robot): robot, stamp_ns, jump_m, turn_rad
        self.restarts: list[dict] = []
        self.drops: Counter[str] = Counter()
        self.update_ms: list[float] = []
        self.trajectory: dict[str, list[tuple[int, np.ndarray]]] = {r: [] for r in robots}
        #: stamps of the updates made while the robot awaited its re-localisation (not reported)
        self.held: dict[str, set[int]] = {r: set() for r in robots}
        self._odom: dict[str, deque[tuple[int, np.ndarray]]] = {r: deque(maxlen=cfg.odom_buffer) for r in robots}
        self._queue: list[tuple[int, int, int, ObservationSet]] = []
        self._queued: set[tuple[str, int]] = set()
        self._seq = 0
        self._latest_obs: dict[str, int] = {}
        self._last: dict[str, tuple[int, np.ndarray]] = {}
        self._reloc_tried: dict[str, int] = {}
        #: stamp of each robot's last set that could re-localise it (relocalize_when_blind)
        self._sighted: dict[str, int] = {}
        #: robots back from a gap, not re-localised yet: (attempts left, stamp the gap began)
        self._returning: dict[str, tuple[int, int]] = {}
        self._wait_ns = int(cfg.max_wait * 1e9)
        self.now_ns = 0  # newest observation stamp received
        self._first_ns: int | None = None

    # ------------------------------------------------------------------ input
    def add_odometry(self, robot: str, stamp_ns: int, pose: np.ndarray) -> bool:
        """Buffer the odometry pose (3,) [m, rad] of ``robot`` at ``stamp_ns``; False if dropped."""
        if robot not in self._odom:
            self.drops["unknown_robot"] += 1
            return False
        pose = np.asarray(pose, float)
        if pose.shape != (3,) or not np.isfinite(pose).all():
            self.drops["bad_odometry"] += 1
            return False
        buf = self._odom[robot]
        if buf and stamp_ns <= buf[-1][0]:
            self.drops["odometry_out_of_order" if stamp_ns < buf[-1][0] else "odometry_duplicate_stamp"] += 1
            return False
        if buf:
            self._check_reset(robot, int(stamp_ns), pose)
        buf.append((int(stamp_ns), pose))
        return True

    def _check_reset(self, robot: str, stamp_ns: int, pose: np.ndarray) -> None:
        """If ``pose`` at ``stamp_ns`` jumped from the robot's previous odometry pose faster than a
        robot drives, its odometry restarted: forget its odometry and gap state and give it a new
        local filter from the new odometry origin, merged into the map like a robot with an
        unknown start. Its queued sets older than the reset find no odometry and are dropped
        (``no_odometry_at_stamp``)."""
        cfg = self.cfg
        last_ns, last = self._odom[robot][-1]
        dt = (stamp_ns - last_ns) * 1e-9
        jump = float(np.hypot(*(pose[:2] - last[:2])))
        turn = float(wrap_angle(pose[2] - last[2]))
        if not ((cfg.odom_reset_speed > 0 and jump > ODOM_RESET_FLOOR[0] + cfg.odom_reset_speed * dt) or (
                cfg.odom_reset_turn_rate > 0 and abs(turn) > ODOM_RESET_FLOOR[1] + cfg.odom_reset_turn_rate * dt)):
            return
        self.restarts.append({"robot": robot, "stamp_ns": stamp_ns, "jump_m": jump, "turn_rad": turn})
        self.drops["odometry_reset"] += 1
        self._odom[robot].clear()
        for state in (self._last, self._returning, self._reloc_tried, self._sighted, self._checked, self._pending,
                      self._agreed):
            state.pop(robot, None)
        self._recent[robot].clear()
        self.local[robot] = self._local_filter(robot)
        self._local_updates[robot] = 0

    def _local_filter(self, robot: str) -> MultiRobotFastSLAM:
        """A K = 1 filter for ``robot`` from the origin of its own (odometry) frame."""
        return MultiRobotFastSLAM(self.cfg.filter, [robot], np.zeros((1, 3)))

    def add_observations(self, obs: ObservationSet) -> bool:
        """Queue an observation set (base_link of ``obs.robot``); False if dropped."""
        if obs.robot not in self._odom:
            self.drops["unknown_robot"] += 1
            return False
        last = self._last.get(obs.robot)
        if last is not None and obs.stamp_ns <= last[0]:
            self.drops["stale_stamp"] += 1
            return False
        key = (obs.robot, int(obs.stamp_ns))
        if key in self._queued:
            self.drops["duplicate_stamp"] += 1
            return False
        if len(self._queue) >= self.cfg.max_queue:
            _, _, _, old = heapq.heappop(self._queue)
            self._queued.discard((old.robot, old.stamp_ns))
            self.drops["queue_overflow"] += 1
        heapq.heappush(self._queue, (int(obs.stamp_ns), self.robots.index(obs.robot), self._seq, obs))
        self._queued.add(key)
        self._seq += 1
        self._latest_obs[obs.robot] = max(self._latest_obs.get(obs.robot, 0), int(obs.stamp_ns))
        self.now_ns = max(self.now_ns, int(obs.stamp_ns))
        if self._first_ns is None:
            self._first_ns = int(obs.stamp_ns)
        return True

    @property
    def queued(self) -> int:
        """Observation sets waiting."""
        return len(self._queue)

    # ------------------------------------------------------------------ processing
    def process(self, flush: bool = False, budget_s: float | None = None, max_sets: int | None = None) -> list[Processed]:
        """Run the filter on every set that is due (all of them with ``flush``), in stamp order,
        or only for about ``budget_s`` wall seconds or ``max_sets`` sets (the rest stays queued)."""
        done: list[Processed] = []
        until = None if budget_s is None else time.perf_counter() + budget_s
        while self._queue and (until is None or time.perf_counter() < until) and (max_sets is None or len(done) < max_sets):
            stamp, _, _, obs = self._queue[0]
            overdue = flush or self.now_ns - stamp > self._wait_ns
            if not overdue and not self._others_caught_up(obs.robot, stamp):
                break
            buf = self._odom[obs.robot]
            if not buf or buf[-1][0] < stamp:
                if not overdue:
                    break  # its odometry is still on the way
                heapq.heappop(self._queue)
                self._queued.discard((obs.robot, stamp))
                self.drops["no_odometry_at_stamp"] += 1
                continue
            heapq.heappop(self._queue)
            self._queued.discard((obs.robot, stamp))
            result = self._update(obs)
            if result is not None:
                done.append(result)
        return done

    def _others_caught_up(self, robot: str, stamp: int) -> bool:
        for other in self.robots:
            # a robot not heard from yet is waited for from the team's first set on
            latest = self._latest_obs.get(other, self._first_ns - 1)
            if other == robot or self.now_ns - latest > self._wait_ns:
                continue  # a robot silent for longer than max_wait is not waited for
            if latest < stamp:
                return False
        return True

    def _update(self, obs: ObservationSet) -> Processed | None:
        buf = self._odom[obs.robot]
        if obs.stamp_ns < buf[0][0]:
            self.drops["no_odometry_at_stamp"] += 1
            return None
        t = np.fromiter((s for s, _ in buf), float, len(buf))
        i = int(np.searchsorted(t, obs.stamp_ns))
        if 0 < i < len(t) and t[i] != obs.stamp_ns and (t[i] - t[i - 1]) * 1e-9 > self.cfg.max_odom_gap:
            self.drops["odometry_gap"] += 1
            return None
        poses = np.array([p for _, p in buf])
        odom = interpolate_poses(np.array([float(obs.stamp_ns)]), t, poses)[0]
        prev = self._last.get(obs.robot)
        # the first update moves the robot from where its odometry started (at its start pose)
        reference = buf[0][1] if prev is None else prev[1]
        filt = self.local.get(obs.robot, self.slam)
        t0 = time.perf_counter()
        motion = between(reference, odom)
        if obs.robot in self._returning:
            seen = self._returning[obs.robot][1]
        elif prev is None:
            seen = obs.stamp_ns
        else:
            seen = self._sighted.get(obs.robot, prev[0]) if self.cfg.relocalize_when_blind else prev[0]
        gap = (obs.stamp_ns - seen) * 1e-9
        tried = self._reloc_tried.get(obs.robot, seen)
        relocalizing = (filt is self.slam and 0 < self.cfg.relocalize_after < gap
                        and self.cfg.filter.observation_model == "stereo_point")
        if relocalizing and len(obs) < self.cfg.fusion.min_inliers and obs.robot not in self._returning:
            # back from silence with too few points to place it (a frontend's tracks start again
            # after a gap): the gap stays open until a set can be aligned, and its sets wait
            self._returning[obs.robot] = (self.cfg.relocalize_tries, seen)
        if relocalizing and obs.stamp_ns - tried >= 1e9 and len(obs) >= self.cfg.fusion.min_inliers:
            self._reloc_tried[obs.robot] = obs.stamp_ns
            left = self._returning.get(obs.robot, (self.cfg.relocalize_tries, seen))[0] - 1
            if self._relocalize(obs, motion, gap, self._path_length(obs.robot, seen, obs.stamp_ns)):
                motion = np.zeros(3)  # the particles are at this stamp already
                left = 0
            if left > 0:
                self._returning[obs.robot] = (left, seen)  # the gap stays open: try again a second later
            else:
                self._returning.pop(obs.robot, None)
        if prev is not None and 0 < self.cfg.sample_gap < (obs.stamp_ns - prev[0]) * 1e-9 and motion.any():
            mid_ns = obs.stamp_ns - 200_000_000
            mid = interpolate_poses(np.array([float(mid_ns)]), t, poses)[0] if mid_ns > buf[0][0] else reference
            try:
                filt.step([RobotUpdate(obs.robot, mid_ns, between(reference, mid), None)])
                motion = between(mid, odom)
            except FilterInputError:
                pass
        obs = self._without_teammates(obs, odom)
        held = obs.robot in self._returning  # its pose is in doubt: its set must not shape the map
        if held:
            self.drops["awaiting_relocalization"] += 1
        elif prev is None or len(obs) >= self.cfg.fusion.min_inliers:
            self._sighted[obs.robot] = obs.stamp_ns
        try:
            filt.step([RobotUpdate(obs.robot, obs.stamp_ns, motion, None if held else obs)])
        except FilterInputError:
            self.drops["bad_observations"] += 1
            return None
        if filt is self.slam and not held:
            self._check_map(obs, odom)
        ms = (time.perf_counter() - t0) * 1e3
        self.update_ms.append(ms)
        self._last[obs.robot] = (obs.stamp_ns, odom)
        if filt is not self.slam:
            self._local_updates[obs.robot] += 1
            if self._local_updates[obs.robot] % self.cfg.merge_every == 0:
                self._try_merge(obs.robot, obs.stamp_ns)
            filt = self.local.get(obs.robot, self.slam)
        est = filt.estimate()
        k = filt.index[obs.robot]
        if filt is self.slam:
            self.trajectory[obs.robot].append((obs.stamp_ns, est.mean[k].copy()))
            if held:
                self.held[obs.robot].add(obs.stamp_ns)
        # a robot back from silence and not placed again has no map pose yet, as an unknown-start
        # robot before its merge: its dead-reckoned pose is neither published nor reported
        merged = filt is self.slam and not held
        return Processed(obs.robot, obs.stamp_ns, est.mean[k].copy(), est.cov[k].copy(), odom, ms, merged)

    def _pose_at(self, robot: str, odom: np.ndarray) -> np.ndarray | None:
        """Where ``robot`` is when its odometry reads ``odom`` (3,): its last estimate moved on by
        its odometry since (map frame, or its own start frame while not merged); None before
        its first update."""
        if not self.trajectory[robot] or robot not in self._last:
            return None
        return compose(self.trajectory[robot][-1][1], between(self._last[robot][1], odom))

    def _without_teammates(self, obs: ObservationSet, odom: np.ndarray) -> ObservationSet:
        """``obs`` without the points on another robot's body (``teammate_radius``)."""
        cfg = self.cfg
        if cfg.teammate_radius <= 0 or len(obs) == 0 or cfg.filter.observation_model != "stereo_point" \
                or obs.robot in self.local:
            return obs
        me = self._pose_at(obs.robot, odom)
        others = []
        for other in self.robots:
            if other == obs.robot or other in self.local or not self._odom[other]:
                continue
            buf = self._odom[other]
            if obs.stamp_ns >= buf[-1][0]:
                at = buf[-1][1]
            else:
                t = np.fromiter((st for st, _ in buf), float, len(buf))
                at = interpolate_poses(np.array([float(obs.stamp_ns)]), t, np.array([q for _, q in buf]))[0]
            pose = self._pose_at(other, at)
            if pose is not None:
                others.append(pose[:2])
        if me is None or not others:
            return obs
        xy = transform_points(me, obs.z[:, :2])
        d = np.linalg.norm(xy[:, None] - np.array(others)[None], axis=2).min(axis=1)
        body = (d < cfg.teammate_radius) & (obs.z[:, 2] < cfg.teammate_height)
        if not body.any():
            return obs
        self.drops["on_teammate"] += int(body.sum())
        keep = ~body
        return ObservationSet(obs.robot, obs.stamp_ns, obs.z[keep], obs.cov[keep], obs.descriptors[keep],
                              obs.track_ids[keep])

    def _path_length(self, robot: str, t0: int, t1: int) -> float:
        """Distance the odometry of ``robot`` covered between stamps ``t0`` and ``t1`` [m]."""
        xy = np.array([p[:2] for s, p in self._odom[robot] if t0 <= s <= t1]).reshape(-1, 2)
        return float(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum())

    def _relocalize(self, obs: ObservationSet, motion: np.ndarray, gap: float, travelled: float) -> bool:
        """Place ``obs.robot``, back after ``gap`` s and ``travelled`` m, by aligning its
        observation set (base_link) to the best particle's map; True if its particles were
        redrawn (logged in :attr:`relocalizations` either way)."""
        from mrslam_core.fusion.alignment import ransac_align
        from mrslam_core.fusion.maps import FusionError, LandmarkMap
        from mrslam_core.geometry.se2 import compose

        slam, k = self.slam, self.slam.index[obs.robot]
        dead = compose(slam.estimate().mean[k], motion)
        entry = {"robot": obs.robot, "stamp_ns": int(obs.stamp_ns), "cause": "gap", "gap_s": gap,
                 "travelled_m": travelled, "accepted": False}
        self.relocalizations.append(entry)
        limit = self.cfg.relocalize_gate + self.cfg.relocalize_drift * travelled
        try:
            frame = LandmarkMap(obs.z, obs.cov, obs.descriptors)
            world = self._map_near(dead, obs.z, limit)
            al = ransac_align(world, frame, self.cfg.fusion)
        except FusionError as exc:
            entry["reason"] = str(exc)
            return False
        entry.update(reason=al.reason, inliers=int(len(al.inliers)))
        if not al.accepted:
            return False
        shift = float(np.hypot(*(al.transform[:2] - dead[:2])))
        entry["shift_m"] = shift
        if shift > limit:
            entry["reason"] = f"the fit is {shift:.2f} m from the dead-reckoned pose (gate {limit:.2f} m)"
            return False
        self._redraw(obs.robot, al.transform, al.cov, (0.02, 0.01))  # a floor for a fit of few points
        entry["accepted"] = True
        return True

    def _check_map(self, obs: ObservationSet, odom: np.ndarray) -> None:
        """Keep ``obs`` (taken at odometry pose ``odom``) among its robot's recent sets and, when
        due, align those sets to the older map and move the robot if the map disagrees
        (:class:`MapCheckConfig`)."""
        mc = self.cfg.map_check
        if mc.every <= 0 or self.cfg.filter.observation_model != "stereo_point":
            return
        slam, k = self.slam, self.slam.index[obs.robot]
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
        from mrslam_core.fusion.alignment import explained, ransac_align
        from mrslam_core.fusion.maps import FusionError

        frame = self._recent_frame(obs.robot, at)
        if frame is None or len(frame.means) < mc.min_inliers:
            self.map_checks["too_few_points"] += 1
            return
        world = self._map_near(est, frame.means, mc.max_shift, obs.stamp_ns - mc.age * 1e9)
        try:
            al = ransac_align(world, frame, replace(self.cfg.fusion, min_inliers=mc.min_inliers))
        except FusionError:
            al = None
        if al is None or not al.accepted:
            self.map_checks["no_fit"] += 1
            self._pending.pop(obs.robot, None)
            return
        shift = float(np.hypot(*(al.transform[:2] - est[:2])))
        turn = float(wrap_angle(al.transform[2] - est[2]))
        if shift <= mc.shift and abs(turn) <= mc.turn:
            self.map_checks["agreed"] += 1
            self._agreed[obs.robot] = int(obs.stamp_ns)
            self._pending.pop(obs.robot, None)
            return
        if shift > mc.max_shift or abs(turn) > mc.max_turn:
            self.map_checks["too_far"] += 1
            return
        dist = self.cfg.fusion.inlier_distance
        support = int(explained(est, world, frame, al.matches, dist, mc.gain_gate, mc.sigma_xy).sum())
        fit_support = (int(explained(al.transform, world, frame, al.matches, dist, mc.gain_gate, mc.sigma_xy).sum())
                       if mc.gain_gate > 0 else len(al.inliers))
        if fit_support - support < mc.min_gain:
            self.map_checks["ambiguous"] += 1
            self._pending.pop(obs.robot, None)
            return
        # a fit of look-alikes disagrees once; the robot is moved when the next check's fit, from
        # other sets, lands where the previous one said the robot would be by now
        before = self._pending.get(obs.robot)
        self._pending[obs.robot] = (int(obs.stamp_ns), at, al.transform)
        if before is None or obs.stamp_ns - before[0] > 1.5 * mc.every * 1e9:
            self.map_checks["unconfirmed"] += 1
            return
        then = compose(before[2], between(before[1], at))
        if (np.hypot(*(then[:2] - al.transform[:2])) > mc.shift
                or abs(float(wrap_angle(then[2] - al.transform[2]))) > mc.turn):
            self.map_checks["unconfirmed"] += 1
            return
        del self._pending[obs.robot]
        self.map_checks["moved"] += 1
        if mc.distrust_moved:
            self._distrusted.append((k, self._agreed.get(obs.robot, -1), int(obs.stamp_ns)))
        self.relocalizations.append({"robot": obs.robot, "stamp_ns": int(obs.stamp_ns), "cause": "map_check",
                                     "accepted": True, "reason": "", "inliers": int(len(al.inliers)),
                                     "estimate_inliers": support, "fit_support": fit_support,
                                     "shift_m": shift, "turn_rad": turn,
                                     "transform": [float(v) for v in al.transform]})
        self._redraw(obs.robot, al.transform, al.cov, (mc.sigma_xy, mc.sigma_theta), int(obs.stamp_ns))

    def _map_near(self, pose: np.ndarray, points: np.ndarray, margin: float, born_before: float | None = None):
        """The best particle's landmarks (a :class:`LandmarkMap`, map frame) that ``points`` (N, ≥2),
        seen from base_link, can be matched to from anywhere within ``margin`` [m] of ``pose`` (3,):
        fewer look-alikes; with ``born_before``, only those created before that stamp [ns]."""
        from mrslam_core.fusion.maps import LandmarkMap

        world = LandmarkMap.from_filter(self.slam)
        reach = margin + float(np.linalg.norm(points[:, :2], axis=1).max()) + self.cfg.fusion.inlier_distance
        keep = np.linalg.norm(world.means[:, :2] - pose[:2], axis=1) <= reach
        if born_before is not None:
            keep &= self.slam.landmarks.born[world.ids] < born_before
        if self._distrusted:
            maker, born = self.slam.landmarks.maker[world.ids], self.slam.landmarks.born[world.ids]
            for k, t0, t1 in self._distrusted:
                keep &= ~((maker == k) & (born >= t0) & (born <= t1))
        return world.subset(np.flatnonzero(keep))

    def _redraw(self, robot: str, fit: np.ndarray, cov: np.ndarray, floor: tuple[float, float],
                stamp_ns: int | None = None) -> None:
        """Draw ``robot``'s pose in every particle from N(fit (3,), cov (3, 3) + diag(floor)²),
        floor = (σ_xy [m], σ_θ [rad]); ``stamp_ns``: the time of those poses (None: no history)."""
        slam = self.slam
        cov = np.nan_to_num(cov) + np.diag([floor[0] ** 2, floor[0] ** 2, floor[1] ** 2])
        chol = np.linalg.cholesky(0.5 * (cov + cov.T))
        draws = fit + (chol @ slam.rng.standard_normal((slam.num_particles, 3, 1)))[..., 0]
        draws[:, 2] = wrap_angle(draws[:, 2])
        slam.add_robot(robot, draws, stamp_ns=stamp_ns)
        if self.cfg.map_check.poses == "estimate":  # the recent sets were placed by the poses just replaced
            self._recent[robot].clear()
            self._pending.pop(robot, None)

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

    def _try_merge(self, robot: str, stamp_ns: int) -> None:
        from mrslam_core.fusion.join import try_join
        from mrslam_core.fusion.maps import FusionError

        try:
            al, joined = try_join(self.slam, self.local[robot], self.cfg.fusion, robot)
        except FusionError as exc:
            self.merges.append({"robot": robot, "stamp_ns": stamp_ns, "accepted": False, "reason": str(exc)})
            return
        self.merges.append({"robot": robot, "stamp_ns": stamp_ns, "accepted": joined is not None,
                            "reason": al.reason, "inliers": int(len(al.inlier_pairs)), "rmse_m": float(al.rmse),
                            "transform": [float(v) for v in al.transform]})
        if joined is not None:
            del self.local[robot]

    # ------------------------------------------------------------------ results
    def trajectories(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """robot -> (stamps (N,) [ns], poses (N, 3) map frame) of every update made in the map
        (not those awaiting a re-localisation)."""
        out = {}
        for r, rows in self.trajectory.items():
            rows = [row for row in rows if row[0] not in self.held[r]]
            stamps = np.array([s for s, _ in rows], np.int64)
            poses = np.array([p for _, p in rows]).reshape(-1, 3)
            out[r] = (stamps, poses)
        return out

    # ------------------------------------------------------------------ checkpoints
    def save(self, path: str | Path) -> Path:
        """Write the filter and the mapper's own state (odometry buffers, queue, last updates,
        trajectories, counters) atomically to ``path`` (see :mod:`mrslam_core.slam.checkpoint`).
        Local filters of unknown-start robots not merged yet are not saved: after a resume those
        robots start their own maps again."""
        from mrslam_core.slam.checkpoint import save_checkpoint

        extra: dict = {"mapper": {
            "robots": self.robots,
            "last": {r: [s, *map(float, p)] for r, (s, p) in self._last.items()},
            "latest_obs": self._latest_obs, "sighted": self._sighted, "first_ns": self._first_ns, "now_ns": self.now_ns,
            "seq": self._seq, "drops": dict(self.drops), "unmerged": sorted(self.local), "restarts": self.restarts,
            "queue": [[o.robot, o.stamp_ns] for _, _, _, o in sorted(self._queue, key=lambda e: e[:3])],
            "checked": self._checked, "map_checks": dict(self.map_checks), "agreed": self._agreed,
            "distrusted": [list(d) for d in self._distrusted],
            "pending": {r: [s, *map(float, at), *map(float, fit)] for r, (s, at, fit) in self._pending.items()},
            "recent": [[r, s, *map(float, at)] for r in self.robots for s, at, _ in self._recent[r]],
        }, "update_ms": np.asarray(self.update_ms, float)}
        recent = [o for r in self.robots for _, _, o in self._recent[r]]
        for i, o in enumerate(recent):
            extra.update({f"recent_z_{i}": o.z, f"recent_cov_{i}": o.cov, f"recent_desc_{i}": o.descriptors,
                          f"recent_tracks_{i}": o.track_ids})
        for i, (_, _, _, o) in enumerate(sorted(self._queue, key=lambda e: e[:3])):
            extra.update({f"queue_z_{i}": o.z, f"queue_cov_{i}": o.cov, f"queue_desc_{i}": o.descriptors,
                          f"queue_tracks_{i}": o.track_ids})
        for k, r in enumerate(self.robots):
            extra[f"odom_t_{k}"] = np.array([t for t, _ in self._odom[r]], np.int64)
            extra[f"odom_p_{k}"] = np.array([p for _, p in self._odom[r]], float).reshape(-1, 3)
            extra[f"traj_t_{k}"] = np.array([t for t, _ in self.trajectory[r]], np.int64)
            extra[f"traj_p_{k}"] = np.array([p for _, p in self.trajectory[r]], float).reshape(-1, 3)
            extra[f"held_t_{k}"] = np.array(sorted(self.held[r]), np.int64)
        return save_checkpoint(self.slam, path, extra)

    @classmethod
    def resume(cls, cfg: CentralConfig, path: str | Path) -> CentralMapper:
        """A mapper in the state :meth:`save` wrote, continuing under ``cfg`` (same robots).

        Raises:
            CheckpointError: unreadable, or saved for other robots.
        """
        from mrslam_core.slam.checkpoint import CheckpointError, load_checkpoint

        slam, extra = load_checkpoint(path)
        state = extra.get("mapper")
        if not isinstance(state, dict) or list(state.get("robots", [])) != list(cfg.robots):
            raise CheckpointError(f"{path}: saved for robots {state and state.get('robots')}, not {list(cfg.robots)}")
        mapper = cls(cfg)
        mapper.slam = slam
        # robots not merged at the checkpoint (unknown start, or restarted) start their own maps again
        unmerged = state.get("unmerged", [r for r in mapper.local if r not in slam.index])
        mapper.local = {r: mapper._local_filter(r) for r in unmerged}
        mapper.restarts = list(state.get("restarts", []))
        mapper._last = {r: (int(v[0]), np.array(v[1:], float)) for r, v in state["last"].items()}
        mapper._latest_obs = {r: int(v) for r, v in state["latest_obs"].items()}
        mapper._sighted = {r: int(v) for r, v in state.get("sighted", {}).items()}
        mapper._first_ns = state["first_ns"]
        mapper.now_ns, mapper._seq = int(state["now_ns"]), int(state["seq"])
        mapper.drops = Counter(state["drops"])
        mapper.update_ms = [float(x) for x in extra["update_ms"]]
        for k, r in enumerate(mapper.robots):
            mapper._odom[r].extend(zip(extra[f"odom_t_{k}"].tolist(), extra[f"odom_p_{k}"]))
            mapper.trajectory[r] = list(zip(extra[f"traj_t_{k}"].tolist(), extra[f"traj_p_{k}"]))
            mapper.held[r] = set(extra[f"held_t_{k}"].tolist()) if f"held_t_{k}" in extra else set()
        for i, (robot, stamp) in enumerate(state["queue"]):
            mapper.add_observations(ObservationSet(robot, int(stamp), extra[f"queue_z_{i}"], extra[f"queue_cov_{i}"],
                                                   extra[f"queue_desc_{i}"], extra[f"queue_tracks_{i}"]))
        mapper.now_ns, mapper._seq = int(state["now_ns"]), int(state["seq"])
        mapper._checked = {r: int(v) for r, v in state.get("checked", {}).items()}
        mapper._agreed = {r: int(v) for r, v in state.get("agreed", {}).items()}
        mapper._distrusted = [tuple(int(x) for x in d) for d in state.get("distrusted", [])]
        mapper.map_checks = Counter(state.get("map_checks", {}))
        mapper._pending = {r: (int(v[0]), np.array(v[1:4], float), np.array(v[4:7], float))
                           for r, v in state.get("pending", {}).items()}
        for i, (robot, stamp, *at) in enumerate(state.get("recent", [])):
            o = ObservationSet(robot, int(stamp), extra[f"recent_z_{i}"], extra[f"recent_cov_{i}"],
                               extra[f"recent_desc_{i}"], extra[f"recent_tracks_{i}"])
            mapper._recent[robot].append((int(stamp), np.array(at, float), o))
        return mapper

    def counters(self) -> dict[str, int]:
        """Drops of the mapper and of the filter, by reason."""
        out = Counter(self.drops)
        out.update({f"filter_{k}": v for k, v in self.slam.dropped.items()})
        for local in self.local.values():
            out.update({f"filter_{k}": v for k, v in local.dropped.items()})
        return dict(out)
