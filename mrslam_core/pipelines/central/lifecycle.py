"""The robots' life cycle: which filter maps each robot, from its start through merges and restarts.

A robot with a known start pose is a robot of the central filter from its first update. A robot
whose start pose is unknown (``unknown_start``) is mapped by a local filter (K = 1, the same
``FilterConfig``) from the origin of its own odometry frame; every ``merge_every`` of its updates
the local best map is aligned to the central one (:func:`~mrslam_core.fusion.join.try_join`),
and once an alignment is accepted the local filter is joined into the central filter. With
``rendezvous`` a robot also joins when it and a robot of the central filter measure each other
(:mod:`mrslam_core.fusion.rendezvous`): sightings and alignments are offered to one
:class:`~mrslam_core.fusion.rendezvous.RendezvousGate`, so that one piece of weak evidence is held
until an independent one agrees. A robot
whose odometry jumps further than a robot drives (its driver restarted, 004 section 5) goes the
same way from its new odometry origin.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import replace
from typing import Any

import numpy as np

from mrslam_core.fusion.acceptance import Evidence
from mrslam_core.fusion.gauge import hold_gauge
from mrslam_core.fusion.rendezvous import RendezvousGate, join_rendezvous, sighting_transform
from mrslam_core.geometry.se2 import wrap_angle
from mrslam_core.pipelines.central.config import ODOM_RESET_FLOOR, CentralConfig
from mrslam_core.slam.checkpoint import filter_from_state, filter_state
from mrslam_core.slam.filter import MultiRobotFastSLAM
from mrslam_core.types import ObservationSet, RobotSighting


class Lifecycle:
    """Known and unknown starts, local filters, merges and odometry resets.

    Args:
        cfg: ``robots``, ``start_poses``, ``unknown_start``, ``merge_every``, ``rendezvous``,
            ``odom_reset_*``, ``filter`` and ``fusion`` apply.
        drops: the mapper's drop counter (by reason), counted into.

    Attributes:
        local: robot -> its local filter (K = 1, the robot's own start frame): the unknown-start
            or restarted robots not merged yet.
        merges: every join attempt: robot, stamp_ns, via ("alignment" or "rendezvous with
            <robot>"), accepted, reason, inliers, rmse_m (None for a rendezvous), transform; an
            accepted one also fused / added / dropped (landmarks).
        gate: the held evidence of the robots not merged (with ``rendezvous``; else None).
        restarts: every odometry reset: robot, stamp_ns, jump_m, turn_rad.

    Raises:
        ValueError: ``start_poses`` not 3 numbers per robot, or ``unknown_start`` naming robots
            not in ``robots``.
    """

    def __init__(self, cfg: CentralConfig, drops: Counter[str]):
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
        self.drops = drops
        self._robots = robots
        self._known = [r for r in robots if r not in unknown]
        self._starts = starts.reshape(len(robots), 3)[[robots.index(r) for r in self._known]]
        self.local = {r: self._local_filter(r) for r in unknown}
        #: updates of each robot's local filter since it was made (merge attempts every merge_every)
        self._updates: Counter[str] = Counter()
        self.merges: list[dict] = []
        self.restarts: list[dict] = []
        self.gate = RendezvousGate.from_config(cfg.fusion) if cfg.rendezvous else None
        #: (observer, target) -> (stamp_ns, z (2,), cov (2, 2)): the last reading of a robot not
        #: merged by a robot of the central filter, or the other way round
        self._readings: dict[tuple[str, str], tuple[int, np.ndarray, np.ndarray]] = {}

    def central_filter(self) -> MultiRobotFastSLAM:
        """A new central filter of the robots with a known start, at their start poses (map frame)."""
        return MultiRobotFastSLAM(self.cfg.filter, self._known, self._starts)

    def hold_gauge(self, slam: MultiRobotFastSLAM) -> bool:
        """While the central filter ``slam`` holds no landmark and ONE robot's start pose fixes
        the map frame, collapse that robot's poses onto their weighted mean
        (:func:`~mrslam_core.fusion.gauge.hold_gauge`): its pose error before the first landmark
        is the frame's own (a gauge no later measurement can observe), and a map made from one
        particle's drawn noise would turn the whole team's frame by it. With several known
        robots only their common motion is such a gauge; their relative poses are observable
        (sightings, shared landmarks) and their spread is kept. True if it collapsed."""
        return len(self._known) == 1 and hold_gauge(slam, self._known)

    def _local_filter(self, robot: str) -> MultiRobotFastSLAM:
        """A K = 1 filter for ``robot`` from the origin of its own (odometry) frame, with a random
        stream of its own (the filter's seed plus 1 + the robot's index): the robots' local
        filters are independent and must not draw the same noise."""
        seed = self.cfg.filter.seed + 1 + self._robots.index(robot)
        return MultiRobotFastSLAM(replace(self.cfg.filter, seed=seed), [robot], np.zeros((1, 3)))

    def restart_if_reset(self, robot: str, last_ns: int, last: np.ndarray, stamp_ns: int, pose: np.ndarray) -> bool:
        """True if the odometry pose (3,) at ``stamp_ns`` jumped from the robot's previous one
        (``last`` at ``last_ns``) faster than a robot drives: its odometry restarted, so the reset
        is logged and counted, and the robot gets a new local filter from its new odometry origin.
        The caller then forgets the robot's odometry and correction state (its queued sets older
        than the reset find no odometry and are dropped as ``no_odometry_at_stamp``)."""
        cfg = self.cfg
        dt = (stamp_ns - last_ns) * 1e-9
        jump = float(np.hypot(*(pose[:2] - last[:2])))
        turn = float(wrap_angle(pose[2] - last[2]))
        if not ((cfg.odom_reset_speed > 0 and jump > ODOM_RESET_FLOOR[0] + cfg.odom_reset_speed * dt) or (
                cfg.odom_reset_turn_rate > 0 and abs(turn) > ODOM_RESET_FLOOR[1] + cfg.odom_reset_turn_rate * dt)):
            return False
        self.restarts.append({"robot": robot, "stamp_ns": stamp_ns, "jump_m": jump, "turn_rad": turn})
        self.drops["odometry_reset"] += 1
        self.local[robot] = self._local_filter(robot)
        self._updates[robot] = 0
        return True

    def updated(self, slam: MultiRobotFastSLAM, robot: str, stamp_ns: int) -> None:
        """Count an update of ``robot``'s local filter; every ``merge_every`` of them, try to
        merge it into the central filter ``slam``."""
        self._updates[robot] += 1
        if self._updates[robot] % self.cfg.merge_every == 0:
            self._try_merge(slam, robot, stamp_ns)

    def _try_merge(self, slam: MultiRobotFastSLAM, robot: str, stamp_ns: int) -> None:
        from mrslam_core.fusion.join import try_join
        from mrslam_core.fusion.maps import FusionError

        try:
            al, joined = try_join(slam, self.local[robot], self.cfg.fusion, robot, self.gate, stamp_ns * 1e-9)
        except FusionError as exc:
            self.merges.append({"robot": robot, "stamp_ns": stamp_ns, "via": "alignment", "accepted": False,
                                "reason": str(exc)})
            return
        self._record(robot, stamp_ns, "alignment", joined, al.reason, al.transform, int(len(al.inlier_pairs)),
                     float(al.rmse))

    def _record(self, robot: str, stamp_ns: int, via: str, joined, reason: str, transform: np.ndarray,
                inliers: int | None, rmse: float | None) -> None:
        entry = {"robot": robot, "stamp_ns": stamp_ns, "via": via, "accepted": joined is not None, "reason": reason,
                 "inliers": inliers, "rmse_m": rmse, "transform": [float(v) for v in transform]}
        if joined is not None:
            entry.update(fused=int(joined.fused), added=int(joined.added), dropped=int(joined.dropped))
            del self.local[robot]
        self.merges.append(entry)

    def rendezvous(self, slam: MultiRobotFastSLAM, sets: list[ObservationSet]) -> None:
        """After a team step: note the sightings of ``sets`` between a robot not merged and a
        robot of ``slam``, and offer each mutual one — the two robots' readings of each other at
        most ``fusion.sighting_pair_window`` apart — to the gate; join the robot when it lets the
        sighting through. The transform uses both robots' weighted-mean poses now."""
        if self.gate is None or not self.local:
            return
        for obs in sets:
            for s in obs.sightings:
                pair = self._mutual(slam, obs.stamp_ns, s)
                if pair is not None:
                    self._offer_sighting(slam, obs.stamp_ns, *pair)
                    if not self.local:
                        return

    def _mutual(self, slam: MultiRobotFastSLAM, stamp_ns: int, s: RobotSighting) -> tuple[str, str] | None:
        """Note sighting ``s`` (at ``stamp_ns``) if it is between a robot not merged and a robot of
        ``slam``; (that robot, the seen one) when the other's reading back lies within the window."""
        i, j = s.observer, s.target
        if i in self.local and j in slam.index:
            pair = (i, j)
        elif j in self.local and i in slam.index:
            pair = (j, i)
        else:
            return None
        self._readings[(i, j)] = (stamp_ns, np.asarray(s.z, float), np.asarray(s.cov, float))
        back = self._readings.get((j, i))
        if back is None or abs(back[0] - stamp_ns) > round(self.cfg.fusion.sighting_pair_window * 1e9):
            return None
        return pair

    def _offer_sighting(self, slam: MultiRobotFastSLAM, stamp_ns: int, robot: str, seen: str) -> None:
        """Offer the mutual sighting of ``robot`` (not merged) and ``seen`` to the gate; join the
        robot if it lets it through."""
        (_, z_rs, cov_rs), (_, z_sr, cov_sr) = self._readings[(robot, seen)], self._readings[(seen, robot)]
        rv = sighting_transform(slam, self.local[robot], seen, z_rs, z_sr, cov_rs, cov_sr)
        via = f"rendezvous with {seen}"
        if self.gate.offer_sighting(robot, stamp_ns * 1e-9, rv) is None:
            self.merges.append({"robot": robot, "stamp_ns": stamp_ns, "via": via, "accepted": False,
                                "reason": self.gate.log[robot][-1]})
            return
        joined = join_rendezvous(slam, self.local[robot], robot, rv, self.cfg.fusion)
        self._record(robot, stamp_ns, via, joined, "", rv.transform, None, None)
        self._readings = {k: v for k, v in self._readings.items() if robot not in k}

    # ------------------------------------------------------------------ checkpoint
    def state(self) -> dict[str, Any]:
        """Everything above as JSON values and arrays: ``unmerged`` (the robots of ``local``),
        ``local_updates``, ``merges``, ``restarts``, the sightings ``readings`` and the gate's held
        evidence ``gate_held`` (with ``rendezvous``), and each local filter's state
        (:func:`~mrslam_core.slam.checkpoint.filter_state`) under ``local_{k}.`` (k: the robot's
        index in ``robots``)."""
        out: dict[str, Any] = {"unmerged": sorted(self.local), "local_updates": dict(self._updates),
                               "merges": [dict(m) for m in self.merges],
                               "restarts": [dict(r) for r in self.restarts],
                               "readings": [[a, b, t, z.tolist(), c.tolist()]
                                            for (a, b), (t, z, c) in self._readings.items()]}
        if self.gate is not None:
            out["gate_held"] = {r: [[t, e.transform.tolist(), e.cov.tolist(), e.kind, e.strong, e.source]
                                    for t, e in held] for r, held in self.gate.held.items()}
        for k, r in enumerate(self._robots):
            if r in self.local:
                out.update({f"local_{k}.{key}": v for key, v in filter_state(self.local[r]).items()})
        return out

    def load_state(self, state: dict[str, Any]) -> None:
        """Take the state :meth:`state` gave (into a new part, of the same robots). Keys a version
        2 checkpoint lacks keep their initial values; its unmerged robots, whose local filters it
        did not hold, start their own maps again."""
        self.local = {}
        for r in state["unmerged"]:
            prefix = f"local_{self._robots.index(r)}."
            saved = {key[len(prefix):]: v for key, v in state.items() if key.startswith(prefix)}
            self.local[r] = filter_from_state(saved, source=f"local filter of {r}") if saved else self._local_filter(r)
        self._updates = Counter(state.get("local_updates", {}))
        self.merges = [dict(m) for m in state.get("merges", [])]
        self.restarts = [dict(r) for r in state.get("restarts", [])]
        self._readings = {(a, b): (int(t), np.asarray(z, float), np.asarray(c, float))
                          for a, b, t, z, c in state.get("readings", [])}
        if self.gate is not None:
            self.gate.held = {r: [(float(t), Evidence(np.asarray(tr, float), np.asarray(cov, float), kind, bool(strong),
                                                      source)) for t, tr, cov, kind, strong, source in held]
                              for r, held in state.get("gate_held", {}).items()}
