"""The robots' life cycle: which filter maps each robot, from its start through merges and restarts.

A robot with a known start pose is a robot of the central filter from its first update. A robot
whose start pose is unknown (``unknown_start``) is mapped by a local filter (K = 1, the same
``FilterConfig``) from the origin of its own odometry frame; every ``merge_every`` of its updates
the local best map is aligned to the central one (:func:`~mrslam_core.fusion.join.try_join`),
and once an alignment is accepted the local filter is joined into the central filter. A robot
whose odometry jumps further than a robot drives (its driver restarted, 004 section 5) goes the
same way from its new odometry origin.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

import numpy as np

from mrslam_core.geometry.se2 import wrap_angle
from mrslam_core.pipelines.central.config import ODOM_RESET_FLOOR, CentralConfig
from mrslam_core.slam.checkpoint import filter_from_state, filter_state
from mrslam_core.slam.filter import MultiRobotFastSLAM


class Lifecycle:
    """Known and unknown starts, local filters, merges and odometry resets.

    Args:
        cfg: ``robots``, ``start_poses``, ``unknown_start``, ``merge_every``, ``odom_reset_*``,
            ``filter`` and ``fusion`` apply.
        drops: the mapper's drop counter (by reason), counted into.

    Attributes:
        local: robot -> its local filter (K = 1, the robot's own start frame): the unknown-start
            or restarted robots not merged yet.
        merges: every alignment attempt: robot, stamp_ns, accepted, reason, inliers, rmse_m,
            transform.
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

    def central_filter(self) -> MultiRobotFastSLAM:
        """A new central filter of the robots with a known start, at their start poses (map frame)."""
        return MultiRobotFastSLAM(self.cfg.filter, self._known, self._starts)

    def _local_filter(self, robot: str) -> MultiRobotFastSLAM:
        """A K = 1 filter for ``robot`` from the origin of its own (odometry) frame."""
        return MultiRobotFastSLAM(self.cfg.filter, [robot], np.zeros((1, 3)))

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
            al, joined = try_join(slam, self.local[robot], self.cfg.fusion, robot)
        except FusionError as exc:
            self.merges.append({"robot": robot, "stamp_ns": stamp_ns, "accepted": False, "reason": str(exc)})
            return
        self.merges.append({"robot": robot, "stamp_ns": stamp_ns, "accepted": joined is not None,
                            "reason": al.reason, "inliers": int(len(al.inlier_pairs)), "rmse_m": float(al.rmse),
                            "transform": [float(v) for v in al.transform]})
        if joined is not None:
            del self.local[robot]

    # ------------------------------------------------------------------ checkpoint
    def state(self) -> dict[str, Any]:
        """Everything above as JSON values and arrays: ``unmerged`` (the robots of ``local``),
        ``local_updates``, ``merges``, ``restarts``, and each local filter's state
        (:func:`~mrslam_core.slam.checkpoint.filter_state`) under ``local_{k}.`` (k: the robot's
        index in ``robots``)."""
        out: dict[str, Any] = {"unmerged": sorted(self.local), "local_updates": dict(self._updates),
                               "merges": [dict(m) for m in self.merges],
                               "restarts": [dict(r) for r in self.restarts]}
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
