"""The central SLAM node: every robot's observations and odometry into ONE multi-robot filter.

Subscribes, per robot listed in the config: its odometry (``odometry``: ``/<robot>/odom``, wheel
odometry, nav_msgs/Odometry odom -> base_link; ``/<robot>/visual_odom``, the frontend's visual
odometry; or both, fused), ``/<robot>/observations`` (PointCloud2 from the frontend, base_link) and
``/<robot>/sightings`` (the other robots it measured, nav_msgs/Odometry from the frontend, joined
to the observation set of their stamp; scored by the filter and, with ``rendezvous``, evidence
for joining a robot with an unknown start). The ordering, pairing with
odometry, the filter and the merging of robots with an unknown start pose (``unknown_start``) live
in :class:`mrslam_core.pipelines.central.CentralMapper`; this node
converts and publishes: ``/<robot>/pose`` (PoseWithCovarianceStamped, map) and map ->
``<robot>/odom`` on /tf after every update of that robot; for a robot not joined yet its pose in
its own start frame (``/<robot>/pose`` in ``<robot>/start``, no /tf), and when it joins
``/<robot>/start_pose`` (PoseStamped, map, latched: the pose of its start frame in the map, i.e.
the join's transform); on a timer (``map_period``) each
robot's ``/<robot>/path`` (when it grew), the best particle's landmarks (``/slam/landmarks``
PointCloud2 and ``/slam/landmark_markers`` ellipsoids), ``/slam/particles`` (PoseArray of every
particle's robot poses) and ``/diagnostics``.

Bad input is counted (``/diagnostics``), never raised out of a callback: unknown robot namespaces
(found by looking at the graph), wrong frames, malformed clouds, stale or duplicated stamps,
clock jumps back, sets without odometry. With ``output_dir`` set, the node writes ``slam.json``
(step latency, drops, landmark count), ``map.npz`` (the best particle's landmarks) and
``estimates.npz`` (``<robot>.t`` [ns] and ``<robot>.pose`` (N, 3) after every update) when it
shuts down.
"""

from __future__ import annotations

import json
import math
import re
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np
from geometry_msgs.msg import PoseArray, PoseStamped, PoseWithCovarianceStamped
from nav_msgs.msg import Odometry, Path as PathMsg
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import InvalidHandle
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy
from sensor_msgs.msg import PointCloud2
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import MarkerArray

from mrslam_core.evaluation.report import latency_summary
from mrslam_core.geometry.se2 import compose, inverse
from mrslam_core.pipelines.central import CentralConfig, CentralMapper, map_move
from mrslam_core.slam.warmup import warm_up
from mrslam_core.types import ObservationSet
from mrslam_ros.conversions import (
    ConversionError,
    cloud_to_observations,
    msg_to_sighting,
    landmark_markers,
    odometry_to_pose,
    odometry_twist_covariance,
    path_msg,
    pose_array_msg,
    pose_stamped_msg,
    pose_with_covariance,
    start_frame,
    transform_msg,
)
from mrslam_ros.diagnostics import Diagnostics
from mrslam_core.pipelines.odometry import OdometrySource
from mrslam_core.slam.config import MotionConfig
from mrslam_ros.params import declare_config, read_config
from mrslam_ros.qos import qos_for_topic
from mrslam_ros.spin import drop_untakeable, run_node

_OBS_TOPIC = re.compile(r"^/([^/]+)/observations$")


@dataclass(frozen=True)
class SlamNodeConfig(CentralConfig):
    """The central node: the mapper's fields plus what the node publishes.

    Attributes:
        map_frame: name of the map frame.
        map_period: period of the path, landmark, particle and diagnostics messages [s].
        max_markers: landmarks drawn as ellipsoids at most (the cloud has all).
        output_dir: folder for slam.json and map.npz at shutdown ("" = none).
        checkpoint: file the node's whole state is saved to, atomically, every
            ``checkpoint_period`` wall seconds and at shutdown ("" = never); docs/checkpoint.md.
        checkpoint_period: wall seconds between checkpoints [s].
        resume: start from ``checkpoint`` when it exists (also ``--resume`` on the command line).
        input_depth: history depth of each observation subscription: a burst the node cannot
            ingest at once waits there (about 2 kB a set) before it reaches the counted queue.
        process_period: wall seconds between runs of the filter that no input started: the
            longest a due set waits when nothing arrives (a set held for a late robot's
            ``max_wait`` or for its odometry); a set or sighting that arrives runs it at once [s].
        process_budget: wall seconds one run may take (at least one set is processed); the rest
            waits, so the callbacks keep draining the subscriptions and a flood overflows the
            mapper's bounded queue (counted, oldest first) instead of the middleware's queues [s].
        discovery_wait: wall seconds a starting (or resumed) node waits for every input topic
            to have a publisher, so that it subscribes transient-local where they keep a history
            and receives what was published before it joined: a node whose subscription matched
            after a robot's odometry began took the first odometry it heard for the robot's start
            pose, and one live faulted run mapped robot1 6.3 deg turned from its first second on
            (docs/reliability.md). A topic still without a publisher then is subscribed as
            soon as its publishers are seen (every 0.2 s), as they offer [s].
        odometry: each robot's odometry source, in ``robots`` order (one entry: every robot):
            ``wheel`` (``/<robot>/odom``), ``visual`` (the frontend's ``/<robot>/visual_odom``,
            for robots without wheel odometry) or ``fused`` (both, step by step weighted by their
            covariances: :mod:`mrslam_core.pipelines.odometry`; the wheel steps' covariance is
            ``wheel_motion``). The robot's odom frame is its source's, and the filter's motion
            model (``filter.motion``) must describe that source's noise.
        wheel_motion: the noise model of the wheel odometry, for ``fused`` robots only (the
            weight of a wheel step against the visual step's own covariance).
    """

    map_frame: str = "map"
    map_period: float = 1.0
    max_markers: int = 2000
    output_dir: str = ""
    checkpoint: str = ""
    checkpoint_period: float = 10.0
    resume: bool = False
    input_depth: int = 1000
    process_period: float = 0.05
    process_budget: float = 0.0
    discovery_wait: float = 3.0
    odometry: tuple[str, ...] = ("wheel",)
    wheel_motion: MotionConfig = field(default_factory=MotionConfig)

    def __post_init__(self) -> None:
        from mrslam_core.pipelines.odometry import SOURCES

        if len(self.odometry) not in (1, len(self.robots)) or any(o not in SOURCES for o in self.odometry):
            raise ValueError(f"odometry must be one of {SOURCES} for every robot, or one for all "
                             f"(got {list(self.odometry)} for {len(self.robots)} robots)")

    def source(self, robot: str) -> str:
        """The odometry source of ``robot``."""
        return self.odometry[0] if len(self.odometry) == 1 else self.odometry[self.robots.index(robot)]


def points_cloud(mean: np.ndarray, stamp_ns: int, frame_id: str) -> PointCloud2:
    """Landmark means (N, 3) [m] -> a PointCloud2 with x y z (covariances go as markers)."""
    from mrslam_ros.conversions import observations_to_cloud

    n = len(mean)
    obs = ObservationSet("map", stamp_ns, np.asarray(mean, float).reshape(n, 3), np.zeros((n, 3, 3)))
    return observations_to_cloud(obs, frame_id)


class SlamNode(Node):
    """Thin wrapper: convert, call :class:`CentralMapper`, publish."""

    def __init__(self, name: str = "slam", resume: bool = False, **kwargs):
        super().__init__(name, **kwargs)
        declare_config(self, SlamNodeConfig())
        self.cfg = read_config(self, SlamNodeConfig)
        self.mapper = self._start_mapper(resume or self.cfg.resume)
        # the compiled kernels load now, before any input is subscribed, not inside the first update
        # or the first map check while the input queues fill (slam/warmup.py, map_move.warm_up)
        loaded = warm_up(self.cfg.filter) + map_move.warm_up()
        self.get_logger().info(f"filter and map check kernels loaded in {loaded:.2f} s")
        # input callbacks (their own group, so a multi-threaded executor drains the subscriptions
        # while the filter runs) and everything else share the mapper under this lock
        self.lock = threading.Lock()
        inputs = MutuallyExclusiveCallbackGroup()
        self.diag = Diagnostics(self, period=self.cfg.map_period, lock=self.lock)
        self.diag.mirror(self.mapper.drops)
        robots = self.mapper.robots
        # each robot's path grows by one pose an update and is sent on the map timer: built anew
        # and sent after every update it cost O(N) an update (14 % of the node's CPU samples in a
        # 60 s demo, growing with the run)
        self.paths: dict[str, PathMsg] = {r: self._path(self.mapper.trajectory[r]) for r in robots}
        self._path_sent = {r: len(p.poses) for r, p in self.paths.items()}  # sent once it grows
        self.pose_pub = {r: self.create_publisher(PoseWithCovarianceStamped, f"/{r}/pose", 10) for r in robots}
        self.path_pub = {r: self.create_publisher(PathMsg, f"/{r}/path", 10) for r in robots}
        self.start_pub = {r: self.create_publisher(PoseStamped, f"/{r}/start_pose", qos_for_topic(f"/{r}/start_pose"))
                          for r in robots}
        self.tf_pub = self.create_publisher(TFMessage, "/tf", 100)
        self.cloud_pub = self.create_publisher(PointCloud2, "/slam/landmarks", 1)
        self.marker_pub = self.create_publisher(MarkerArray, "/slam/landmark_markers", 1)
        self.particle_pub = self.create_publisher(PoseArray, "/slam/particles", 1)
        self._odometry = {r: OdometrySource(self.cfg.source(r), self.cfg.wheel_motion) for r in robots}
        odometry_specs = []
        for r in robots:
            if self._odometry[r].uses_wheel:
                odometry_specs.append((Odometry, f"/{r}/odom", partial(self.on_odom, r), 100))
            if self._odometry[r].uses_visual:
                odometry_specs.append((Odometry, f"/{r}/visual_odom", partial(self.on_visual_odom, r), 100))
        topics = [spec[1] for spec in odometry_specs] + [f"/{r}/observations" for r in robots]
        self._wait_for_publishers(topics, self.cfg.discovery_wait)  # learn who keeps a history first
        #: input subscriptions, odometry first: :meth:`drain` empties them in this order
        # transient-local where every publisher keeps a history: a node that starts late or
        # restarts receives what was published before it joined (qos.py); volatile otherwise, so
        # any publisher matches. A topic with no publisher yet, or a robot's kept sets before its
        # odometry is heard, is subscribed later by :meth:`adapt_inputs` (None until then).
        self._inputs_group = inputs
        # sightings before observation sets: drained first, they wait for their set in the mapper.
        # Optional (a team without tags has no publisher): subscribed at once, volatile, if no
        # publisher is there yet, instead of waited for.
        sighting_specs = [(Odometry, f"/{r}/sightings", partial(self.on_sightings, r), self.cfg.input_depth)
                          for r in robots]
        self._optional_inputs = {spec[1] for spec in sighting_specs}
        self._input_specs = odometry_specs + sighting_specs + [
            (PointCloud2, f"/{r}/observations", partial(self.on_observations, r), self.cfg.input_depth) for r in robots]
        #: robots whose odometry has been heard (their kept observation sets are subscribed only then)
        self.odometry_heard: set[str] = set()
        self.inputs: list = []
        for i in range(len(self._input_specs)):
            self.inputs.append(self._subscribe_input(i))
        if silent := [t for t in self.unsubscribed if not self.get_publishers_info_by_topic(t)]:
            self.get_logger().info(f"no publisher after {self.cfg.discovery_wait:.1f} s for {silent}: "
                                   "subscribing each as its publishers appear")
        if self.unsubscribed:
            self._adapt_timer = self.create_timer(0.2, self.adapt_inputs, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.unknown: set[str] = set()
        self.latency_ms: deque[float] = deque(maxlen=100_000)
        # what a resumed mapper logged before its checkpoint is not logged again
        self._merges_logged, self._relocs_logged, self._restarts_logged = (
            len(self.mapper.merges), len(self.mapper.relocalizations), len(self.mapper.restarts))
        for m in self.mapper.merges:  # a resumed node latches the joins it made before again
            if m["accepted"] and m["robot"] not in self.mapper.local:
                self._publish_join(m)
        self.create_timer(self.cfg.map_period, self.on_timer)
        # the filter runs when a set or sighting comes in and again after each set while sets are
        # due (the guard condition), and on a slow timer for a set that waits on time alone (a late
        # robot's max_wait, its odometry). A 100 Hz poll cost a fifth of a core with nothing to do
        # (a node with the same subscriptions and timers: 0.20 of a core at 100 Hz, 0.04 at 20 Hz)
        self._wake = self.create_guard_condition(self.on_process)
        self.create_timer(self.cfg.process_period, self.on_process, clock=Clock(clock_type=ClockType.STEADY_TIME))
        if self.cfg.checkpoint:
            self.create_timer(self.cfg.checkpoint_period, self.save_checkpoint,
                              clock=Clock(clock_type=ClockType.STEADY_TIME))

    def _start_mapper(self, resume: bool) -> CentralMapper:
        path = Path(self.cfg.checkpoint) if self.cfg.checkpoint else None
        if resume and path is not None and path.is_file():
            mapper = CentralMapper.resume(self.cfg, path)  # a bad checkpoint stops the node here, loudly
            n = sum(len(t) for t in mapper.trajectory.values())
            self.get_logger().info(f"resumed from {path}: {n} updates, {mapper.slam.landmarks.size} landmark slots")
            return mapper
        if resume:
            self.get_logger().warning(f"--resume: no checkpoint at {path or '(checkpoint not set)'}; starting afresh")
        return CentralMapper(self.cfg)

    def save_checkpoint(self) -> None:
        """Save the whole state to ``checkpoint`` (atomic: a crash keeps the previous one)."""
        t0 = time.perf_counter()
        with self.lock:
            self.mapper.save(self.cfg.checkpoint)
        self.diag.set("checkpoint_ms", (time.perf_counter() - t0) * 1e3)

    # ------------------------------------------------------------------ callbacks
    def on_odom(self, robot: str, msg: Odometry) -> None:
        """Wheel odometry: the robot's odometry, or the wheel half of its fused odometry."""
        try:
            stamp, pose, _ = odometry_to_pose(msg)
        except ConversionError as exc:
            self.diag.count("bad_odometry", f"{robot}: {exc}")
            return
        self._add_odometry(robot, self._odometry[robot].wheel(stamp, pose))

    def on_visual_odom(self, robot: str, msg: Odometry) -> None:
        """The frontend's visual odometry: the robot's odometry, or the visual half of its fused one."""
        try:
            stamp, pose, _ = odometry_to_pose(msg)
            twist_cov = odometry_twist_covariance(msg)
        except ConversionError as exc:
            self.diag.count("bad_odometry", f"{robot}: {exc}")
            return
        source = self._odometry[robot]
        self._add_odometry(robot, source.visual(stamp, pose, twist_cov))
        if source.fusion is not None:
            self.diag.mirror({"odometry_not_fused": source.dropped}, detail=robot)

    def _add_odometry(self, robot: str, poses: list[tuple[int, np.ndarray]]) -> None:
        if not poses:
            return
        self.odometry_heard.add(robot)
        with self.lock:
            for stamp, pose in poses:
                self.mapper.add_odometry(robot, stamp, pose)
            self.diag.mirror(self.mapper.drops, detail=robot)

    def on_observations(self, robot: str, msg: PointCloud2) -> None:
        if msg.header.frame_id not in (f"{robot}/base_link", "base_link"):
            self.diag.count("wrong_frame", f"{robot}: observations in {msg.header.frame_id!r}")
            return
        try:
            obs = cloud_to_observations(msg, robot)
        except ConversionError as exc:
            self.diag.count("bad_cloud", f"{robot}: {exc}")
            return
        with self.lock:
            self.mapper.add_observations(obs)
            self.diag.mirror(self.mapper.drops, detail=robot)
        self._wake.trigger()

    def on_sightings(self, robot: str, msg: Odometry) -> None:
        """Another robot measured by ``robot`` (its tag): into the mapper, to join the set of its stamp."""
        try:
            stamp, sighting = msg_to_sighting(msg, robot)
        except ConversionError as exc:
            self.diag.count("bad_sighting", f"{robot}: {exc}")
            return
        with self.lock:
            self.mapper.add_sightings(robot, stamp, [sighting])
            self.diag.mirror(self.mapper.drops, detail=robot)
        self._wake.trigger()

    def on_process(self) -> None:
        """Take every waiting input (:meth:`drain`), then run the filter on what is due, one set at
        a time, for at most ``process_budget`` s, and publish; if it ran, come back in the next
        executor cycle for the sets still due. A flood overflows the mapper's counted queue rather
        than the middleware's queues."""
        until = time.perf_counter() + self.cfg.process_budget
        self.drain()
        while True:
            with self.lock:
                done = self.mapper.process(max_sets=1)
                self.diag.mirror(self.mapper.drops)
                self.diag.mirror(self.mapper.slam.dropped, "filter_")
            if not done:
                return
            d = done[0]
            if time.perf_counter() >= until:
                until = -1.0  # publish this one, then give the subscriptions their turn
            self.latency_ms.append((self.get_clock().now().nanoseconds - d.stamp_ns) * 1e-6)
            self._log_merges()
            if d.merged:  # an unknown-start robot has no map pose (nor map -> odom) before it merges
                self.publish(d.robot, d.stamp_ns, d.pose, d.cov, d.odom)
            elif d.robot in self.mapper.local:  # its own start frame, for the exploration node
                self.pose_pub[d.robot].publish(pose_with_covariance(d.pose, d.cov, d.stamp_ns, start_frame(d.robot)))
            if until < 0:
                self._wake.trigger()
                return

    def drain(self) -> None:
        """Hand every message waiting in the input subscriptions to its callback, odometry first.

        The executor takes one message per subscription per cycle and a filter step runs in
        between; in a flood the sets would wait in the middleware's queue (``input_depth``) and
        the latency would grow to that queue's length. Taken here, they reach the mapper, whose
        bounded queue drops the oldest and counts them.
        """
        for sub in self.inputs:
            if sub is None:
                continue
            for _ in range(self.cfg.input_depth):
                try:
                    with sub.handle:
                        got = sub.handle.take_message(sub.msg_type, sub.raw)
                except InvalidHandle:  # destroyed at shutdown
                    return
                except RuntimeError as exc:  # a sample rclpy cannot convert
                    drop_untakeable(self, exc)
                    break
                if got is None:
                    break
                sub.callback(got[0])

    def _wait_for_publishers(self, topics: list[str], timeout: float) -> None:
        """Until every topic has a publisher in the graph (discovery), at most ``timeout`` wall s."""
        until = time.monotonic() + timeout
        while time.monotonic() < until and not all(self.get_publishers_info_by_topic(t) for t in topics):
            time.sleep(0.05)

    def _subscribe_input(self, i: int):
        """Subscribe input ``i`` of ``_input_specs`` as its publishers offer (see ``inputs``);
        None, and left for :meth:`adapt_inputs`, while it has none or, for a robot's observation
        sets kept transient-local, until the robot's odometry has been heard. The two histories
        of a starting node arrive independently: sets taken before their odometry are overdue at
        once (the newest set is seconds ahead of them) and were dropped as
        ``no_odometry_at_stamp``, 3.4 s of robot1's in one CI run (docs/reliability.md)."""
        from mrslam_ros.qos import adapted_to_publishers

        msg_type, topic, callback, depth = self._input_specs[i]
        infos = self.get_publishers_info_by_topic(topic)
        if not infos:
            if topic in self._optional_inputs:
                return self.create_subscription(msg_type, topic, callback, depth, callback_group=self._inputs_group)
            return None
        qos = adapted_to_publishers(infos, topic, depth)
        robots = self.mapper.robots
        first_set = len(self._input_specs) - len(robots)  # the observation sets follow the odometry
        if (i >= first_set and qos.durability == DurabilityPolicy.TRANSIENT_LOCAL
                and robots[i - first_set] not in self.odometry_heard):
            return None
        return self.create_subscription(msg_type, topic, callback, qos, callback_group=self._inputs_group)

    def adapt_inputs(self) -> None:
        """Subscribe the inputs whose publishers were discovered after the wait, and the observation
        sets of robots whose odometry has been heard since the last call. A subscription
        made before them could not know whether they keep a history: volatile, it would miss
        what they published before it matched (the simulator's clock may start before a slow
        discovery ends, and a robot's first odometry is its start); transient-local, it would
        never match a volatile publisher."""
        for i, sub in enumerate(self.inputs):
            if sub is None and (sub := self._subscribe_input(i)) is not None:
                self.inputs[i] = sub
                self.get_logger().info(f"{self._input_specs[i][1]}: subscribed "
                                       f"{sub.qos_profile.durability.name.lower()}")
        if not self.unsubscribed:
            self._adapt_timer.cancel()

    @property
    def unsubscribed(self) -> list[str]:
        """The input topics not subscribed yet, for want of a publisher (or of odometry heard)."""
        return [spec[1] for spec, sub in zip(self._input_specs, self.inputs) if sub is None]

    def _log_merges(self) -> None:
        for m in self.mapper.merges[self._merges_logged:]:
            via = m.get("via", "alignment")  # a checkpoint of an earlier version has no "via"
            if m["accepted"]:
                self._publish_join(m)
            if m["accepted"] and via == "alignment":
                self.get_logger().info(f"{m['robot']} merged into the map by map alignment: transform "
                                       f"{m['transform']}, {m['inliers']} inliers, rmse {m['rmse_m']:.3f} m")
            elif m["accepted"]:
                self.get_logger().info(f"{m['robot']} merged into the map by {via}: transform {m['transform']}")
            else:
                self.get_logger().info(f"{m['robot']} not merged yet: {m['reason']}", throttle_duration_sec=10.0)
        self._merges_logged = len(self.mapper.merges)
        for e in self.mapper.relocalizations[self._relocs_logged:]:
            if e["cause"] == "map_check":
                self.get_logger().warning(f"{e['robot']} contradicted the older map: the map check moved it by "
                                          f"{e['shift_m']:.2f} m, {math.degrees(e['turn_rad']):.1f} deg "
                                          f"({e['inliers']} inliers)")
            elif e["accepted"]:
                self.get_logger().info(f"{e['robot']} back after {e['gap_s']:.1f} s: re-localised on the map "
                                       f"({e['inliers']} inliers, {e['shift_m']:.2f} m from dead reckoning)")
            else:
                self.get_logger().warning(f"{e['robot']} back after {e['gap_s']:.1f} s, not re-localised: {e['reason']}")
        self._relocs_logged = len(self.mapper.relocalizations)
        for e in self.mapper.restarts[self._restarts_logged:]:
            self.get_logger().warning(f"{e['robot']}: odometry jumped {e['jump_m']:.2f} m / {e['turn_rad']:.2f} rad "
                                      "(restarted): mapped on its own until its map aligns with the team's")
        self._restarts_logged = len(self.mapper.restarts)

    def _publish_join(self, merge: dict) -> None:
        """``/<robot>/start_pose``: where a join put the robot's start frame in the map."""
        pose = np.asarray(merge["transform"], float)
        self.start_pub[merge["robot"]].publish(pose_stamped_msg(pose, int(merge["stamp_ns"]), self.cfg.map_frame))

    def on_timer(self) -> None:
        self._look_for_unknown_robots()
        with self.lock:
            _, mean, cov, _, _ = self.mapper.slam.best_map()
            poses = self.mapper.slam.poses.reshape(-1, 3).copy()
            update_ms = self.mapper.update_ms[-500:]
            queued = self.mapper.queued
        stamp = self.get_clock().now().nanoseconds
        if len(mean):
            self.cloud_pub.publish(points_cloud(mean, stamp, self.cfg.map_frame))
            if self.marker_pub.get_subscription_count():
                n = min(len(mean), self.cfg.max_markers)
                self.marker_pub.publish(landmark_markers(mean[:n], cov[:n], stamp, self.cfg.map_frame))
        if self.particle_pub.get_subscription_count():
            self.particle_pub.publish(pose_array_msg(poses, stamp, self.cfg.map_frame))
        for robot, path in self.paths.items():
            if len(path.poses) != self._path_sent[robot] and self.path_pub[robot].get_subscription_count():
                self._path_sent[robot] = len(path.poses)
                path.header.stamp = path.poses[-1].header.stamp
                self.path_pub[robot].publish(path)
        for name, values in (("update_ms", update_ms), ("latency_ms", list(self.latency_ms)[-500:])):
            if values:
                s = latency_summary(np.asarray(values))
                for key in ("p50", "p95", "max"):
                    self.diag.set(f"{name}.{key}", s[key])
        self.diag.set("landmarks", float(len(mean)))
        self.diag.set("queued", float(queued))
        self.diag.set("updates", float(len(self.latency_ms)))

    def _path(self, trajectory: list[tuple[int, np.ndarray]]) -> PathMsg:
        """nav_msgs/Path of a mapper trajectory [(stamp_ns, pose (3,) map frame)]."""
        return path_msg(np.array([p for _, p in trajectory], float).reshape(-1, 3),
                        np.array([t for t, _ in trajectory], np.int64), self.cfg.map_frame)

    def _look_for_unknown_robots(self) -> None:
        for topic, _ in self.get_topic_names_and_types():
            m = _OBS_TOPIC.match(topic)
            if m and m.group(1) not in self.mapper.robots and topic not in self.unknown:
                self.unknown.add(topic)
                self.diag.count("unknown_robot", f"{topic} is published but {m.group(1)!r} is not in robots")

    # ------------------------------------------------------------------ output
    def publish(self, robot: str, stamp: int, pose: np.ndarray, cov: np.ndarray, odom: np.ndarray) -> None:
        self.pose_pub[robot].publish(pose_with_covariance(pose, cov, stamp, self.cfg.map_frame))
        self.paths[robot].poses.append(pose_stamped_msg(pose, stamp, self.cfg.map_frame))
        map_to_odom = compose(pose, inverse(odom))  # map <- odom = map <- base ⊕ base <- odom
        self.tf_pub.publish(TFMessage(transforms=[transform_msg(map_to_odom, stamp, self.cfg.map_frame, f"{robot}/odom")]))

    def write_outputs(self) -> None:
        """slam.json and map.npz into ``output_dir`` (nothing when it is empty)."""
        if not self.cfg.output_dir:
            return
        out = Path(self.cfg.output_dir)
        out.mkdir(parents=True, exist_ok=True)
        slots, mean, cov, desc, count = self.mapper.slam.best_map()
        np.savez(out / "map.npz", slots=slots, mean=mean, cov=cov, descriptors=desc, count=count)
        est = self.mapper.trajectories()
        np.savez(out / "estimates.npz", **{f"{r}.t": t for r, (t, _) in est.items()},
                 **{f"{r}.pose": p for r, (_, p) in est.items()})
        drops = dict(self.diag.drops)
        stats = {
            "update_ms": latency_summary(np.asarray(self.mapper.update_ms)),
            "update_ms_all": [round(x, 3) for x in self.mapper.update_ms],
            "latency_ms": latency_summary(np.asarray(self.latency_ms)),
            "updates": {r: len(p.poses) for r, p in self.paths.items()},
            "landmarks": int(len(mean)),
            "dropped": drops,
            "queued_at_end": self.mapper.queued,
            "merges": self.mapper.merges,
            "relocalizations": self.mapper.relocalizations,
            "map_checks": dict(self.mapper.map_checks),
            "restarts": self.mapper.restarts,
            "outlier_matches": self.mapper.slam.outlier_pairs / self.mapper.slam.num_particles,
            "unmerged": sorted(self.mapper.local),
        }
        (out / "slam.json").write_text(json.dumps(stats, indent=1))

    def destroy_node(self) -> None:
        try:
            if self.cfg.checkpoint:
                self.save_checkpoint()
            self.write_outputs()
        finally:
            super().destroy_node()


def main(argv: list[str] | None = None) -> int:
    """``python -m mrslam_ros.slam_node [--resume] --ros-args ...``."""
    argv = list(sys.argv if argv is None else argv)
    resume = "--resume" in argv
    return run_node(partial(SlamNode, resume=resume), [a for a in argv if a != "--resume"])


if __name__ == "__main__":
    sys.exit(main())
