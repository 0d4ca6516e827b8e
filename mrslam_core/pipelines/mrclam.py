"""``mrslam mrclam DIR``: the multi-robot filter on a UTIAS MR.CLAM dataset.

All robots run in ONE filter (``mode: joint``) or one filter each (``mode: independent``, the
baseline). Landmarks are associated by descriptor only: the barcode a robot reads is turned into a
one-hot descriptor, so the filter gets no landmark ids, only appearance. Measurements of other
robots' barcodes become range-bearing likelihood terms in the joint filter (each particle holds
every robot's pose). Start poses come from ground truth at the first common timestamp.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal

import numpy as np

from mrslam_core.configio import ConfigError, load_yaml, profile_section
from mrslam_core.datasets.mrclam import MrclamDataset, OdometryIntegrator
from mrslam_core.evaluation.report import write_run
from mrslam_core.slam.config import FilterConfig
from mrslam_core.slam.filter import MultiRobotFastSLAM, RobotUpdate
from mrslam_core.types import ObservationSet, RobotSighting


#: the MR.CLAM profile (in configio.PROFILES): MrclamConfig's filter default
MRCLAM_PROFILE = "mrclam.yaml"


@dataclass(frozen=True)
class MrclamConfig:
    """The MR.CLAM run.

    Attributes:
        filter: the filter (range-bearing model); by default the MR.CLAM profile
            (config/mrclam.yaml).
        sigma_range, sigma_bearing: landmark measurement noise [m], [rad] (dataset 6 against
            Vicon: 0.12–0.19 m, 0.009–0.019 rad).
        sigma_sighting_range, sigma_sighting_bearing: noise of robot-to-robot measurements
            [m], [rad] (the barcode sits off the robot's centre, so larger).
        use_sightings: score robot-to-robot measurements in the particle weights.
        step_period: filter step period [s]; measurements are grouped into these windows.
        robots: robot numbers to run (1..5).
        mode: one joint filter, or independent single-robot filters.
        duration: seconds from the start to process (None: all).
        estimate: the pose reported per step: the best particle's (eq. 14) or the weighted mean.
        odometry_delay: seconds by which the logged (commanded) velocities precede the motion
            they cause; 0.25 s on dataset 6 (it minimises the heading error of 1 s odometry
            increments against Vicon: 0.041 rad undelayed, 0.026 rad delayed).
    """

    filter: FilterConfig = field(default_factory=lambda: profile_section(FilterConfig, MRCLAM_PROFILE, "filter"))
    sigma_range: float = 0.15
    sigma_bearing: float = 0.02
    sigma_sighting_range: float = 0.25
    sigma_sighting_bearing: float = 0.04
    use_sightings: bool = True
    step_period: float = 0.2
    robots: tuple[int, ...] = (1, 2, 3, 4, 5)
    mode: Literal["joint", "independent"] = "joint"
    duration: float | None = None
    estimate: Literal["best", "mean"] = "mean"
    odometry_delay: float = 0.25


def _one_hot(subjects: np.ndarray, n: int = 21) -> np.ndarray:
    d = np.zeros((subjects.size, n), np.float32)
    d[np.arange(subjects.size), subjects.astype(int)] = 1.0
    return d


def _bins(times: np.ndarray, t0: float, period: float) -> np.ndarray:
    """Step index k >= 1 of each time: the window (t0 + (k−1)·period, t0 + k·period]."""
    return np.maximum(np.ceil((times - t0) / period - 1e-9), 1).astype(np.int64)


def run(ds: MrclamDataset, cfg: MrclamConfig, progress: bool = False) -> dict:
    """Run the filter(s); returns trajectories, step times, maps, counters.

    Returns:
        {"trajectories": {robot: {"t", "est", "gt", "odom"}}, "update_ms": (S,),
         "landmarks": {"mean", "cov"} of the (first) filter's best particle, "dropped": {...}}
    """
    t0, t1 = ds.time_span()
    if cfg.duration is not None:
        t1 = min(t1, t0 + cfg.duration)
    nsteps = int(np.floor((t1 - t0) / cfg.step_period))
    times = t0 + cfg.step_period * np.arange(nsteps + 1)
    names = [f"robot{i}" for i in cfg.robots]
    robot_of = {i: f"robot{i}" for i in cfg.robots}
    starts = np.array([ds.groundtruth(i, np.array([t0]))[0] for i in cfg.robots])
    odo = {i: OdometryIntegrator(ds.robots[i].odometry, cfg.odometry_delay) for i in cfg.robots}
    lm_cov = np.diag([cfg.sigma_range**2, cfg.sigma_bearing**2])
    rr_cov = np.diag([cfg.sigma_sighting_range**2, cfg.sigma_sighting_bearing**2])

    # per robot: step index -> measurements in that window, sorted by time, one per subject
    # and timestamp (a frame that reads the same barcode twice keeps the last reading)
    per_step: dict[int, dict[int, np.ndarray]] = {}
    for i in cfg.robots:
        m = ds.robots[i].measurements
        m = m[(m[:, 0] > t0) & (m[:, 0] <= times[-1])]
        order = np.lexsort((m[:, 1], m[:, 0]))
        m = m[order]
        keep = np.ones(len(m), bool)
        keep[:-1] = (m[1:, 0] != m[:-1, 0]) | (m[1:, 1] != m[:-1, 1])
        m = m[keep]
        k = _bins(m[:, 0], t0, cfg.step_period)
        splits = np.flatnonzero(np.diff(k)) + 1
        per_step[i] = {int(kk[0]): mm for kk, mm in zip(np.split(k, splits), np.split(m, splits)) if len(kk)}

    if cfg.mode == "joint":
        groups = [list(cfg.robots)]
    else:
        groups = [[i] for i in cfg.robots]
    filters = [
        MultiRobotFastSLAM(
            replace(cfg.filter, seed=cfg.filter.seed + g), [robot_of[i] for i in grp],
            starts[[cfg.robots.index(i) for i in grp]],
        )
        for g, grp in enumerate(groups)
    ]
    est = {n: np.zeros((nsteps + 1, 3)) for n in names}
    for n, s in zip(names, starts):
        est[n][0] = s

    def robot_update(i: int, grp: list[int], frame: np.ndarray, ta: float, tb: float) -> RobotUpdate:
        """Robot i's update: odometry from ta to tb [s], and what it measured at tb."""
        stamp = int(round((tb - t0) * 1e9))
        is_lm = frame[:, 1] > ds.num_robots
        lm = frame[is_lm]
        obs = None
        if len(lm):
            obs = ObservationSet(
                robot_of[i], stamp, lm[:, 2:4], np.broadcast_to(lm_cov, (len(lm), 2, 2)), _one_hot(lm[:, 1])
            )
        sightings = []
        if cfg.use_sightings and len(grp) > 1:
            for row in frame[~is_lm]:
                if int(row[1]) in grp:
                    sightings.append(RobotSighting(robot_of[i], robot_of[int(row[1])], row[2:4], rr_cov))
        return RobotUpdate(robot_of[i], stamp, odo[i].delta(ta, tb), obs, sightings)

    step_ms = []
    report_every = max(nsteps // 10, 1)
    for k in range(1, nsteps + 1):
        t_start = time.perf_counter()
        for slam, grp in zip(filters, groups):
            updates = []
            for i in grp:
                m = per_step[i].get(k, np.zeros((0, 4)))
                t_prev = times[k - 1]
                for t_meas in np.unique(m[:, 0]):
                    frame = m[m[:, 0] == t_meas]
                    updates.append(robot_update(i, grp, frame, t_prev, t_meas))
                    t_prev = t_meas
                if t_prev < times[k]:
                    updates.append(robot_update(i, grp, m[:0], t_prev, times[k]))
            slam.step(updates)
        step_ms.append((time.perf_counter() - t_start) * 1e3)
        for slam, grp in zip(filters, groups):
            poses = slam.estimate().mean if cfg.estimate == "mean" else slam.estimate().poses
            for j, i in enumerate(grp):
                est[robot_of[i]][k] = poses[j]
        if progress and k % report_every == 0:
            print(f"  step {k}/{nsteps} ({100 * k // nsteps}%)", file=sys.stderr, flush=True)

    trajectories = {}
    for n, i in zip(names, cfg.robots):
        trajectories[n] = {
            "t": times - 0.0,
            "est": est[n],
            "gt": ds.groundtruth(i, times),
            "odom": odo[i].trajectory(starts[cfg.robots.index(i)], times),
        }
    slots, mean, cov, _, _ = filters[0].best_map()
    dropped: dict[str, int] = {}
    for slam in filters:
        for key, v in slam.dropped.items():
            dropped[key] = dropped.get(key, 0) + v
    return {
        "trajectories": trajectories,
        "update_ms": np.array(step_ms),
        "landmarks": {"mean": mean, "cov": cov},
        "dropped": dropped,
        "resamples": [slam.resamples for slam in filters],
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
        extra={"dataset": str(args.folder), "dropped": res["dropped"], **landmark_errors(ds, res["landmarks"])},
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
