"""A public stereo sequence (KITTI odometry, EuRoC/ASL) through the frontends and the central
mapper, offline, as fast as it goes: ``mrslam dataset run FORMAT PATH --out DIR``.

Each robot (one per segment with ``split``) has its own stereo frontend. Its visual odometry is
the robot's odometry (the datasets have no wheels): per frame, the frontend's base_link pose,
projected into the plane (x, y, yaw), goes to :meth:`CentralMapper.add_odometry` and its
observation set to :meth:`CentralMapper.add_observations`, in stamp order across the robots: the
same calls, in the same order, that the central node makes on live topics. Robots 2..K start
known (their ground-truth start in the map frame) or, with ``unknown_start``, are mapped on their
own and merged by map alignment (``join_unknown``).

The report holds, per robot, the filter's ATE against the ground truth, the visual odometry's
alone (``odom_ate_rmse_m``; the same stamps), the visual odometry's end-point error in 3D
(``vo_endpoint_error_m``, and as a percentage of the distance driven) and its heading error at the
end (``vo_heading_error_deg``), where the odometry ends up from its start (``vo_end_translation_m``,
``vo_end_rotation_deg``: the drift of a camera that stood still), and the frontend's points per
frame and failed motions.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from mrslam_core.datasets.stereo import StereoSequence
from mrslam_core.evaluation.metrics import interpolate_poses
from mrslam_core.frontend.config import FrontendConfig
from mrslam_core.frontend.frontend import Frontend
from mrslam_core.geometry.se2 import between, compose, planar_from_matrix, wrap_angle
from mrslam_core.pipelines.central import CentralConfig, CentralMapper


@dataclass(frozen=True)
class DatasetRunConfig(CentralConfig):
    """``mrslam dataset run``: the central mapper's fields (as the central node has them; its
    ``robots``, ``start_poses`` and ``unknown_start`` come from the data) plus:

    Attributes:
        split: robots made of the sequence: K consecutive segments driven at the same time.
        join_unknown: robots 2..K start at unknown poses and join by map alignment (robot1's
            start defines the map frame); otherwise every robot starts at its ground-truth pose.
        max_frames: use at most this many frames of the sequence (0: all).
        frontend: the robots' stereo frontends.
    """

    split: int = 1
    join_unknown: bool = False
    max_frames: int = 0
    frontend: FrontendConfig = field(default_factory=FrontendConfig)

    def __post_init__(self) -> None:
        if self.split < 1:
            raise ValueError("split must be >= 1")
        if self.max_frames < 0:
            raise ValueError("max_frames must be >= 0 (0: all)")


def vo_endpoint(vo: np.ndarray, gt: np.ndarray) -> dict[str, float]:
    """End-point errors of a visual odometry track against ground truth, both from one start.

    Args:
        vo: (N, 4, 4) the odometry's poses, odom frame (the first is the identity).
        gt: (N, 4, 4) ground-truth poses, map frame, at the same frames.

    Returns:
        ``vo_endpoint_error_m`` (3D distance of the last poses after putting the odometry at the
        ground truth's start), ``distance_m`` (the ground truth's path length),
        ``vo_endpoint_error_pct`` and ``vo_heading_error_deg`` (yaw difference at the end).
    """
    rel_gt = np.linalg.inv(gt[0]) @ gt[-1]
    rel_vo = np.linalg.inv(vo[0]) @ vo[-1]
    err = float(np.linalg.norm(rel_vo[:3, 3] - rel_gt[:3, 3]))
    dist = float(np.linalg.norm(np.diff(gt[:, :3, 3], axis=0), axis=1).sum())
    dyaw = planar_from_matrix(rel_vo)[2] - planar_from_matrix(rel_gt)[2]
    return {"vo_endpoint_error_m": err, "distance_m": dist,
            "vo_endpoint_error_pct": 100.0 * err / dist if dist > 0 else float("nan"),
            "vo_heading_error_deg": float(np.degrees(wrap_angle(dyaw)))}


def run(sequence: StereoSequence, cfg: DatasetRunConfig, progress=None) -> dict:
    """Run the sequence's robots through their frontends and ONE central mapper.

    Args:
        sequence: the whole sequence (cut by ``cfg.split``).
        cfg: the run's config.
        progress: a callable ``progress(done, total)`` after each frame, or None.

    Returns:
        trajectories (robot -> {"t", "est", "gt", "odom"} for :func:`write_run`), the mapper's
        step times, map, counters and the per-robot frontend figures.
    """
    if cfg.max_frames and cfg.max_frames < len(sequence):
        sequence = StereoSequence(sequence.name, sequence.format, sequence.rig,
                                  sequence.frames[:cfg.max_frames],
                                  None if sequence.ground_truth is None else sequence.ground_truth[:cfg.max_frames],
                                  sequence.notes)
    segments = sequence.split(cfg.split)
    names = [f"robot{j + 1}" for j in range(len(segments))]
    starts = np.zeros((len(names), 3))
    for j, seg in enumerate(segments):
        if seg.ground_truth is not None:
            starts[j] = planar_from_matrix(seg.ground_truth[0])
    central = replace(cfg, robots=tuple(names), start_poses=tuple(float(v) for v in starts.ravel()),
                      unknown_start=tuple(names[1:]) if cfg.join_unknown else ())
    mapper = CentralMapper(central)
    frontends = {n: Frontend(seg.rig, cfg.frontend, robot=n) for n, seg in zip(names, segments)}
    events = sorted((f.stamp_ns, j, i) for j, seg in enumerate(segments) for i, f in enumerate(seg.frames))
    vo = {n: [] for n in names}
    points = {n: [] for n in names}
    unusable = {n: 0 for n in names}
    wall = time.perf_counter()
    frontend_s = 0.0
    for done, (stamp, j, i) in enumerate(events):
        name, seg, fe = names[j], segments[j], frontends[names[j]]
        try:
            left, right = seg.read(i)
        except ValueError:  # DatasetError: a frame that cannot be read is counted, the run goes on
            unusable[name] += 1
            continue
        t0 = time.perf_counter()
        obs, _ = fe.step(left, right, int(stamp))
        frontend_s += time.perf_counter() - t0
        if obs is None:
            unusable[name] += 1
            continue
        vo[name].append((i, fe.odometry.pose))
        points[name].append(len(obs))
        mapper.add_odometry(name, int(stamp), planar_from_matrix(fe.odometry.pose))
        mapper.add_observations(obs)
        mapper.process()
        if progress is not None:
            progress(done + 1, len(events))
    mapper.process(flush=True)
    est = mapper.trajectories()
    trajectories, vo_figures = {}, {}
    for j, (name, seg) in enumerate(zip(names, segments)):
        t, poses = est.get(name, (np.zeros(0, np.int64), np.zeros((0, 3))))
        idx = np.array([i for i, _ in vo[name]], np.int64)
        odo = np.array([p for _, p in vo[name]]).reshape(-1, 4, 4)
        tr = {"t": t * 1e-9, "est": poses, "gt": None, "odom": None}
        if len(idx):
            stamps = seg.stamps_ns[idx].astype(float)
            planar = planar_from_matrix(odo)
            odo_planar = compose(starts[j], between(planar[0], planar))
            tr["odom"] = interpolate_poses(t.astype(float), stamps, odo_planar) if len(t) else None
            if seg.ground_truth is not None:
                gt_planar = seg.planar_ground_truth()[idx]
                tr["gt"] = interpolate_poses(t.astype(float), stamps, gt_planar) if len(t) else None
                vo_figures[name] = vo_endpoint(odo, seg.ground_truth[idx])
        pts = np.array(points[name])
        fe = frontends[name]
        if len(odo):  # where the visual odometry ends up, from its start (a still camera: its drift)
            rel = np.linalg.inv(odo[0]) @ odo[-1]
            vo_figures.setdefault(name, {}).update({
                "vo_end_translation_m": float(np.linalg.norm(rel[:3, 3])),
                "vo_end_rotation_deg": float(np.degrees(np.arccos(np.clip((np.trace(rel[:3, :3]) - 1) / 2, -1, 1)))),
            })
        vo_figures.setdefault(name, {}).update({
            "frames": len(seg), "unusable_frames": unusable[name], "vo_failures": fe.vo_failures,
            "points_per_frame_mean": float(pts.mean()) if pts.size else 0.0,
            "frames_with_max_points": float(np.mean(pts >= cfg.frontend.max_observations)) if pts.size else 0.0,
            "frontend_drops": dict(fe.drops),
        })
        trajectories[name] = tr
    _, mean, cov, _, _ = mapper.slam.best_map()
    frames = sum(len(v) for v in vo.values())
    return {
        "trajectories": trajectories, "update_ms": np.array(mapper.update_ms), "landmarks": {"mean": mean, "cov": cov},
        "robots": vo_figures, "dropped": mapper.counters(), "merges": mapper.merges,
        "relocalizations": mapper.relocalizations,
        "frontend_ms_mean": 1e3 * frontend_s / max(frames, 1), "wall_s": time.perf_counter() - wall,
        "start_poses": {n: starts[j].tolist() for j, n in enumerate(names)},
    }
