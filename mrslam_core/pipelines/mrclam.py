"""``mrslam mrclam DIR``: the multi-robot filter on a UTIAS MR.CLAM dataset, through the central mapper.

The dataset is fed to :class:`~mrslam_core.pipelines.central.CentralMapper` as a live team would
feed it: each robot's odometry poses (dead reckoning from the logged velocities, at the log's
samples) through ``add_odometry``, and one observation set per measurement frame
through ``add_observations``, so the mapper's ordering, pairing and corrections run on real data.
All robots share ONE mapper (``mode: joint``) or have one each (``mode: independent``, the
baseline). Landmarks are associated by descriptor only: the barcode a robot reads is turned into a
one-hot descriptor, so the filter gets no landmark ids, only appearance. A frame's readings of
other robots' barcodes travel in its set as sightings (:class:`~mrslam_core.types.RobotSighting`)
and become range-bearing likelihood terms in the joint filter (each particle holds every robot's
pose). Start poses come from ground truth at the first common timestamp.
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path
from typing import Any, Literal

import numpy as np

from mrslam_core.configio import PROFILES, ConfigError, load_profile, load_yaml
from mrslam_core.datasets.mrclam import MrclamCalibration, MrclamDataset, OdometryIntegrator
from mrslam_core.evaluation.metrics import interpolate_poses
from mrslam_core.evaluation.report import latency_summary, write_run
from mrslam_core.pipelines.central import CentralConfig, CentralMapper, MapCheckConfig
from mrslam_core.slam.config import FilterConfig
from mrslam_core.types import ObservationSet, RobotSighting


#: the MR.CLAM profile (in configio.PROFILES): the defaults of MrclamConfig's mapper fields it sets
MRCLAM_PROFILE = "mrclam.yaml"


@lru_cache(maxsize=1)
def _profile() -> CentralConfig:
    """The central mapper's fields as the MR.CLAM profile sets them (read once)."""
    return load_profile(CentralConfig, PROFILES / MRCLAM_PROFILE)


def _from_profile(name: str) -> Any:
    """A field whose default is the MR.CLAM profile's value of the mapper's field ``name``."""
    return field(default_factory=lambda: getattr(_profile(), name))


@dataclass(frozen=True)
class MrclamConfig(CentralConfig):
    """The MR.CLAM run: the central mapper's fields (``filter``, ``team_step``, ``map_check``,
    ``relocalize_after``, ...; defaults from the MR.CLAM profile, config/mrclam.yaml, where it
    sets them; ``start_poses`` come from the data) plus:

    Attributes:
        robots: robots to run, ``robot<i>`` for the dataset's robot i (1..5).
        start_poses: not used: every robot starts at its Vicon pose at the first common stamp.
        team_step: the mapper's team step (> 0 here): every robot's motion is also brought to
            the end of each window by a set without observations if it measured nothing at
            that instant, and the reported trajectories are sampled there [s].
        calibration: how the logs relate to the robots' motion and to the scene (the camera
            reads depth along its axis; the robots execute less than the commanded velocity):
            applied to the dataset before anything reads it.
        sigma_range: landmark range noise of calibrated readings [m]. This σ and the three
            below are those of a contaminated normal fitted to dataset 6's residuals against
            Vicon, each camera on its own line, all robots pooled (``mrslam experiment
            mrclam_calibration``; outlier shares 0.3–0.6 %); the bearing σ are those fitted
            before the cameras' bearing offsets (under them: 0.0108 and 0.0102 rad, measured
            and not adopted: robot 4 worse, docs/results.md).
        sigma_bearing: landmark bearing noise [rad].
        sigma_sighting_range: range noise of robot-to-robot readings [m].
        sigma_sighting_bearing: bearing noise of robot-to-robot readings [rad].
        use_sightings: put robot-to-robot measurements into the sets (scored in the particle
            weights).
        mode: one joint filter (one mapper), or independent single-robot filters (one mapper
            per robot, no sightings).
        duration: seconds from the start to process (None: all).
        odometry_delay: seconds by which the logged (commanded) velocities precede the motion
            they cause; 0.25 s on dataset 6 (it minimises the heading error of 1 s odometry
            increments against Vicon: 0.041 rad undelayed, 0.026 rad delayed).
    """

    robots: tuple[str, ...] = ("robot1", "robot2", "robot3", "robot4", "robot5")
    start_poses: tuple[float, ...] = ()
    team_step: float = _from_profile("team_step")
    relocalize_after: float = _from_profile("relocalize_after")
    map_check: MapCheckConfig = _from_profile("map_check")
    filter: FilterConfig = _from_profile("filter")
    calibration: MrclamCalibration = field(default_factory=MrclamCalibration)
    sigma_range: float = 0.042
    sigma_bearing: float = 0.012
    sigma_sighting_range: float = 0.026
    sigma_sighting_bearing: float = 0.011
    use_sightings: bool = True
    mode: Literal["joint", "independent"] = "joint"
    duration: float | None = None
    odometry_delay: float = 0.25

    def __post_init__(self) -> None:
        bad = [r for r in self.robots if not re.fullmatch(r"robot[1-9][0-9]*", r)]
        if bad or not self.robots:
            raise ValueError(f"robots must be names robot<i> of the dataset's robots, got {list(self.robots)}")
        if not self.team_step > 0:
            raise ValueError("team_step must be > 0: the window every robot's motion reaches")

    @property
    def numbers(self) -> tuple[int, ...]:
        """The dataset's robot numbers of ``robots``."""
        return tuple(robot_number(r) for r in self.robots)


def robot_number(name: str) -> int:
    """The MR.CLAM robot number of ``robot<i>``."""
    return int(name[len("robot"):])


def _one_hot(subjects: np.ndarray, n: int = 21) -> np.ndarray:
    d = np.zeros((subjects.size, n), np.float32)
    d[np.arange(subjects.size), subjects.astype(int)] = 1.0
    return d


def measurement_frames(ds: MrclamDataset, robot: int, t0: float, t1: float) -> list[np.ndarray]:
    """Robot ``robot``'s measurements in (t0, t1] [s] as frames: one (n, 4) array (t, subject,
    range, bearing) per timestamp, in time order, one reading per subject (a frame that reads the
    same barcode twice keeps the last reading)."""
    m = ds.robots[robot].measurements
    m = m[(m[:, 0] > t0) & (m[:, 0] <= t1)]
    m = m[np.lexsort((m[:, 1], m[:, 0]))]
    keep = np.ones(len(m), bool)
    keep[:-1] = (m[1:, 0] != m[:-1, 0]) | (m[1:, 1] != m[:-1, 1])
    m = m[keep]
    return np.split(m, np.flatnonzero(np.diff(m[:, 0])) + 1) if len(m) else []


def observation_sets(ds: MrclamDataset, cfg: MrclamConfig, robot: str, team: tuple[str, ...],
                     t0: float, t1: float) -> list[ObservationSet]:
    """Robot ``robot``'s sets in (t0, t1] [s], stamps in ns from t0: one per measurement frame
    (its landmark readings as range-bearing with a one-hot barcode descriptor; its readings of
    the ``team``'s other robots as sightings, with ``use_sightings``) and one without
    observations at the end of every ``team_step`` window in which no frame fell on that
    instant (the robot's motion up to there)."""
    lm_cov = np.diag([cfg.sigma_range**2, cfg.sigma_bearing**2])
    rr_cov = np.diag([cfg.sigma_sighting_range**2, cfg.sigma_sighting_bearing**2])
    targets = {robot_number(r): r for r in team} if cfg.use_sightings and len(team) > 1 else {}
    sets = []
    for frame in measurement_frames(ds, robot_number(robot), t0, t1):
        stamp = int(round((frame[0, 0] - t0) * 1e9))
        lm = frame[frame[:, 1] > ds.num_robots]
        sightings = tuple(RobotSighting(robot, targets[int(row[1])], row[2:4].copy(), rr_cov)
                          for row in frame if int(row[1]) in targets)
        sets.append(ObservationSet(robot, stamp, lm[:, 2:4], np.broadcast_to(lm_cov, (len(lm), 2, 2)),
                                   _one_hot(lm[:, 1]), sightings=sightings))
    period_ns = int(round(cfg.team_step * 1e9))
    ends = period_ns * np.arange(1, int(np.floor((t1 - t0) / cfg.team_step + 1e-9)) + 1)
    taken = {o.stamp_ns for o in sets}
    sets += [ObservationSet(robot, int(s), np.zeros((0, 2)), np.zeros((0, 2, 2))) for s in ends if int(s) not in taken]
    return sorted(sets, key=lambda o: o.stamp_ns)


def odometry_knots(odo: OdometryIntegrator, t0: float) -> np.ndarray:
    """The stamps (N,) int64 [ns from t0 [s]] of the log's samples (delayed), distinct, sorted."""
    return np.unique(np.round((odo.t - t0) * 1e9).astype(np.int64))


def odometry_poses(odo: OdometryIntegrator, t0: float, knots: np.ndarray, after_ns: int,
                   end_ns: int) -> tuple[np.ndarray, np.ndarray]:
    """The dead reckoning's poses to feed for the stamps in (after_ns, end_ns] [ns from t0 [s]]:
    at the log's samples (``knots``, :func:`odometry_knots`), at ``end_ns``, and at 0 if that is
    in the span: the mapper's linear interpolation between them is ``odo``'s own.

    Returns:
        (stamps (N,) int64 [ns], poses (N, 3) odom frame [m, rad], θ unwrapped)."""
    inside = knots[np.searchsorted(knots, after_ns, "right"):np.searchsorted(knots, end_ns, "left")]
    stamps = np.concatenate([[0] if after_ns < 0 <= end_ns and (not inside.size or inside[0] != 0) else [],
                             inside, [end_ns]]).astype(np.int64)
    return stamps, odo.pose(t0 + stamps * 1e-9)


def run(ds: MrclamDataset, cfg: MrclamConfig, progress: bool = False) -> dict:
    """Feed the dataset to the central mapper(s); returns trajectories, step times, maps, counters.

    Returns:
        {"trajectories": {robot: {"t", "est", "gt", "odom"}} at the ``team_step`` grid,
         "update_ms": (S,) wall time per team step of all the mappers' work (feeding, ordering,
         filter steps) [ms], "mapper_ms": the mappers' own update times [ms], "landmarks": {"mean",
         "cov"} of the (first) mapper's best particle, "dropped": the mappers' counters summed,
         "resamples": per mapper, "merges": every join attempt of a robot in ``unknown_start``
         (:attr:`~mrslam_core.pipelines.central.lifecycle.Lifecycle.merges`)}; the estimate of a
         robot in ``unknown_start`` is NaN before its merge
    """
    ds = ds.calibrated(cfg.calibration)
    t0, t1 = ds.time_span()
    if cfg.duration is not None:
        t1 = min(t1, t0 + cfg.duration)
    nsteps = int(np.floor((t1 - t0) / cfg.team_step + 1e-9))
    times = t0 + cfg.team_step * np.arange(nsteps + 1)
    t1 = times[-1]
    starts = {r: ds.groundtruth(robot_number(r), np.array([t0]))[0] for r in cfg.robots}
    odo = {r: OdometryIntegrator(ds.robots[robot_number(r)].odometry, cfg.odometry_delay) for r in cfg.robots}
    groups = [cfg.robots] if cfg.mode == "joint" else [(r,) for r in cfg.robots]
    mappers = [
        CentralMapper(replace(cfg, robots=grp, start_poses=tuple(float(v) for r in grp for v in starts[r]),
                              filter=replace(cfg.filter, seed=cfg.filter.seed + g)))
        for g, grp in enumerate(groups)
    ]
    sets = [{r: observation_sets(ds, cfg, r, grp, t0, t1) for r in grp} for grp in groups]
    period_ns = int(round(cfg.team_step * 1e9))
    knots = {r: odometry_knots(odo[r], t0) for r in cfg.robots}
    cursor = [{r: 0 for r in grp} for grp in groups]  # each robot's next set to feed

    step_ms = []
    report_every = max(nsteps // 10, 1)
    for k in range(1, nsteps + 1):
        tic = time.perf_counter()
        end = k * period_ns
        for mapper, grp, mine, at in zip(mappers, groups, sets, cursor):
            for r in grp:
                stamps, poses = odometry_poses(odo[r], t0, knots[r], -1 if k == 1 else end - period_ns, end)
                for s, p in zip(stamps.tolist(), poses):
                    mapper.add_odometry(r, s, p)
                while at[r] < len(mine[r]) and mine[r][at[r]].stamp_ns <= end:
                    mapper.add_observations(mine[r][at[r]])
                    at[r] += 1
            mapper.process(flush=k == nsteps)
        step_ms.append((time.perf_counter() - tic) * 1e3)
        if progress and k % report_every == 0:
            print(f"  step {k}/{nsteps} ({100 * k // nsteps}%)", file=sys.stderr, flush=True)

    trajectories = {}
    grid = (period_ns * np.arange(nsteps + 1)).astype(float)  # the window ends [ns from t0]
    for mapper in mappers:
        for r, (stamps, poses) in mapper.trajectories().items():
            est = np.vstack([starts[r], interpolate_poses(grid[1:], stamps.astype(float), poses)]) if len(stamps) \
                else np.full((len(times), 3), np.nan)
            if r in cfg.unknown_start and len(stamps):  # no map pose before its merge
                est[grid < stamps[0]] = np.nan
            trajectories[r] = {"t": times - 0.0, "est": est, "gt": ds.groundtruth(robot_number(r), times),
                               "odom": odo[r].trajectory(starts[r], times)}
    _, mean, cov, _, _ = mappers[0].slam.best_map()
    dropped: dict[str, int] = {}
    for mapper in mappers:
        for key, v in mapper.counters().items():
            dropped[key] = dropped.get(key, 0) + v
    return {
        "trajectories": {r: trajectories[r] for r in cfg.robots},
        "update_ms": np.array(step_ms),
        "mapper_ms": np.concatenate([np.asarray(m.update_ms, float) for m in mappers]),
        "landmarks": {"mean": mean, "cov": cov},
        "dropped": dropped,
        "resamples": [m.slam.resamples for m in mappers],
        "merges": [dict(e) for m in mappers for e in m.merges],
    }


def landmark_errors(ds: MrclamDataset, landmarks: dict) -> dict[str, float]:
    """Distance from each ground-truth landmark to the nearest mapped landmark [m]."""
    if len(landmarks["mean"]) == 0:
        return {"landmark_rmse_m": float("nan")}
    d = np.linalg.norm(ds.landmarks[:, None, 1:3] - landmarks["mean"][None, :, :2], axis=2).min(axis=1)
    return {"landmark_rmse_m": float(np.sqrt(np.mean(d * d))), "landmark_max_m": float(d.max())}


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="mrslam mrclam", description=__doc__)
    ap.add_argument("folder", help="a MR.CLAM dataset folder (e.g. ../shared/data/mrclam/dataset6)")
    ap.add_argument("--out", default="runs/mrclam")
    ap.add_argument("--config", help="YAML with MrclamConfig keys (see config/mrclam.yaml)")
    ap.add_argument("--particles", type=int, help="override filter.num_particles")
    ap.add_argument("--mode", choices=["joint", "independent"])
    ap.add_argument("--no-sightings", action="store_true", help="ignore robot-to-robot measurements")
    ap.add_argument("--duration", type=float, help="seconds to process from the start")
    ap.add_argument("--seed", type=int)
    args = ap.parse_args(argv)
    try:
        cfg = load_yaml(MrclamConfig, args.config) if args.config else MrclamConfig()
    except ConfigError as exc:
        print(f"mrslam mrclam: {exc}", file=sys.stderr)
        return 2
    if args.particles:
        cfg = replace(cfg, filter=replace(cfg.filter, num_particles=args.particles))
    if args.seed is not None:
        cfg = replace(cfg, filter=replace(cfg.filter, seed=args.seed))
    if args.mode:
        cfg = replace(cfg, mode=args.mode)
    if args.no_sightings:
        cfg = replace(cfg, use_sightings=False)
    if args.duration:
        cfg = replace(cfg, duration=args.duration)
    ds = MrclamDataset(args.folder)
    print(f"MR.CLAM {args.folder}: robots {cfg.robots}, mode {cfg.mode}, M={cfg.filter.num_particles}", flush=True)
    res = run(ds, cfg, progress=True)
    report = write_run(
        args.out, res["trajectories"], cfg, res["update_ms"], res["landmarks"], ds.landmarks[:, 1:3],
        extra={"dataset": str(args.folder), "dropped": res["dropped"], "resamples": res["resamples"],
               "mapper_update_ms": latency_summary(res["mapper_ms"]), **landmark_errors(ds, res["landmarks"])},
    )
    for name, r in report["robots"].items():
        print(f"  {name}: ATE {r['ate_rmse_m']:.3f} m (odometry {r['odom_ate_rmse_m']:.3f} m, "
              f"ratio {r['ate_over_odom']:.2f}), RPE {r['rpe_rmse_m']:.3f} m")
    mean_ate = np.mean([r["ate_rmse_m"] for r in report["robots"].values()])
    u = report["update_ms"]
    print(f"  mean ATE {mean_ate:.3f} m; landmarks {report['landmarks']}; step p50 {u['p50']:.2f} ms "
          f"p95 {u['p95']:.2f} ms max {u['max']:.2f} ms")
    print(f"wrote {Path(args.out) / 'report.json'}")
    return 0
