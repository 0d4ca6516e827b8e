"""A recorded run read back: trajectories, the last map and diagnostics out of a bag.

Both ``mrslam demo`` (live run) and ``mrslam replay --offline`` build their report from here, so
the two reports measure the same way: the estimate at each update stamp against ground truth and
dead reckoning interpolated at those stamps.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mrslam_core.evaluation.metrics import interpolate_poses
from mrslam_core.geometry.se2 import between, compose
from mrslam_ros.bag import message_class, read_bag


@dataclass
class Series:
    """Stamped planar poses: ``t`` (N,) [ns], ``poses`` (N, 3) [m, rad]."""

    t: list[int] = field(default_factory=list)
    poses: list[np.ndarray] = field(default_factory=list)

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        return np.array(self.t, np.int64), np.array(self.poses, float).reshape(-1, 3)


def deserialize(data: bytes, msgtype: str):
    """CDR bytes of a bag -> the rclpy message."""
    from rclpy.serialization import deserialize_message

    return deserialize_message(data, message_class(msgtype))


def read_series(bag: str | Path, robots: Iterable[str], kinds: Iterable[str] = ("pose", "ground_truth", "odom")
                ) -> dict[str, dict[str, Series]]:
    """robot -> kind -> :class:`Series` from ``/<robot>/<kind>`` (Odometry or PoseWithCovarianceStamped).
    A robot's poses in its own start frame (``<robot>/start``, before it joined the map) are left
    out: they are in no frame the others are."""
    from mrslam_ros.conversions import ConversionError, msg_to_pose, stamp_to_ns, start_frame

    robots, kinds = list(robots), list(kinds)
    out = {r: {k: Series() for k in kinds} for r in robots}
    topics = {f"/{r}/{k}": (r, k) for r in robots for k in kinds}
    for m in read_bag(bag, topics):
        r, k = topics[m.topic]
        msg = deserialize(m.data, m.msgtype)
        if msg.header.frame_id == start_frame(r):
            continue
        try:
            pose = msg_to_pose(msg.pose.pose)
        except ConversionError:
            continue
        out[r][k].t.append(stamp_to_ns(msg.header.stamp))
        out[r][k].poses.append(pose)
    return out


def evaluation_trajectories(est: dict[str, tuple[np.ndarray, np.ndarray]], series: dict[str, dict[str, Series]],
                            starts: dict[str, np.ndarray]) -> dict[str, dict]:
    """The ``trajectories`` argument of :func:`mrslam_core.evaluation.report.write_run`.

    Args:
        est: robot -> (stamps (N,) [ns], poses (N, 3) map frame) of the filter's estimates.
        series: :func:`read_series` output with ``ground_truth`` (map) and ``odom`` (odom frame).
        starts: robot -> (3,) start pose in the map frame (dead reckoning is composed onto it).

    Estimates outside the span of the ground truth or odometry are left out.
    """
    out = {}
    for r, (t, poses) in est.items():
        gt_t, gt = series[r]["ground_truth"].arrays()
        od_t, od = series[r]["odom"].arrays()
        if not len(t) or len(gt_t) < 2 or len(od_t) < 2:
            continue
        keep = (t >= max(gt_t[0], od_t[0])) & (t <= min(gt_t[-1], od_t[-1]))
        t, poses = t[keep], poses[keep]
        tf = t.astype(float)
        gt_at = interpolate_poses(tf, gt_t.astype(float), gt)
        od_at = interpolate_poses(tf, od_t.astype(float), od)
        dead = np.array([compose(starts[r], between(od[0], p)) for p in od_at]).reshape(-1, 3)
        out[r] = {"t": t * 1e-9, "est": poses, "gt": gt_at, "odom": dead}
    return out


def last_message(bag: str | Path, topic: str):
    """The last message on ``topic`` (rclpy object), or None."""
    last = None
    for m in read_bag(bag, [topic]):
        last = m
    return None if last is None else deserialize(last.data, last.msgtype)


def diagnostics(bag: str | Path) -> dict[str, dict[str, float]]:
    """The last /diagnostics values of every node in the bag: {status name: {key: value}}."""
    from mrslam_ros.conversions import diagnostics_to_counters

    out: dict[str, dict[str, float]] = {}
    for m in read_bag(bag, ["/diagnostics"]):
        out.update(diagnostics_to_counters(deserialize(m.data, m.msgtype)))
    return out
