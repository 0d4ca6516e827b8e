"""``mrslam experiment baseline_gtsam DIR``: a GTSAM factor-graph baseline on MR.CLAM (issue 28).

The same parsed and calibrated data as the filter (:func:`mrslam_core.pipelines.mrclam.run`,
``MrclamConfig.calibration``) — odometry with the same delay, the same measurements (one reading per subject and stamp, barcodes → subjects),
robot-to-robot sightings, ground-truth start poses at the first common timestamp — go into one
factor graph over all robots:

- a pose per robot every ``period`` s on the filter's time grid ``t0 + period·k`` (the grid the
  filter reports and is evaluated on);
- ``BetweenFactorPose2`` between consecutive poses from the logged (v, ω) integrated over the
  interval (:class:`~mrslam_core.datasets.mrclam.OdometryIntegrator`), with the covariance of the
  filter's own MR.CLAM motion model (:func:`mrslam_core.slam.motion.predict_motion` with
  ``MrclamConfig().filter.motion``, config/mrclam.yaml), moved from the start pose's frame into the frame
  of the end pose, which is where GTSAM's Pose2 between error lives;
- ``BearingRangeFactor2D`` (landmarks) and ``BearingRangeFactorPose2`` (other robots) with the
  filter's MR.CLAM measurement noise (``MrclamConfig.sigma_*``), each behind a Huber loss
  (k = 1.345). A measurement is attached to the robot's pose nearest its time after
  being re-expressed in that pose's frame through the robot's own odometry between the two times
  (≤ period/2). For a sighting the other robot's motion over that interval is not compensated
  (≤ 0.1 s at ≤ 0.2 m/s: ≤ 0.02 m);
- a tight prior (1 mm, 1 mrad) on each robot's ground-truth start pose, which fixes the map frame
  (so ATE is unaligned, as for the filter); no landmark ground truth: a landmark's initial value
  comes from its first sighting from the dead-reckoned pose.

``--known 1`` keeps the prior on robot 1's start pose only, as ``mrslam experiment fusion_mrclam``
knows it: the other robots' frames then come from the measurements alone, and the batch solution
is the best any estimator can make of the same data with that one start pose. Their dead
reckoning (the initial estimate) still begins at the true start poses, so that Levenberg–Marquardt
finds the minimum nearest the truth: the smoother's best case. iSAM2 is not run then (a robot
without a prior has no estimate until measurements link it).

Solved (a) in batch by Levenberg–Marquardt from dead reckoning and (b) online by iSAM2, with the
factors of each pose time added in one update (``--isam-every`` groups several pose times per
update); the online estimate of a pose is iSAM2's estimate right after the update that added it —
the causal estimate, comparable with the filter's per-step weighted mean. ATE RMSE against Vicon
interpolated to the pose times (:func:`mrslam_core.evaluation.metrics.ate_rmse`), as the filter's
report. ``--filter-report`` puts a ``mrslam mrclam`` run's per-robot ATE beside them.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from mrslam_core.datasets.mrclam import MrclamDataset, OdometryIntegrator
from mrslam_core.evaluation.metrics import ate_rmse
from mrslam_core.experiments._output import write_tables
from mrslam_core.experiments.fusion_mrclam import gauge_free
from mrslam_core.geometry.se2 import compose
from mrslam_core.pipelines.mrclam import MrclamConfig
from mrslam_core.slam.motion import predict_motion, reports_motion

HUBER_K = 1.345
PRIOR_SIGMA = (1e-3, 1e-3, 1e-3)  # m, m, rad: start poses at ground truth


@dataclass
class GraphSteps:
    """A factor graph split by pose time: ``factors[k]`` / ``values[k]`` are what pose time k adds
    (every robot's pose k with its prior or odometry factor, the measurements attached to pose k,
    and the landmarks first seen there).

    Attributes:
        factors: per pose time, a ``gtsam.NonlinearFactorGraph``.
        values: per pose time, a ``gtsam.Values`` of the new variables' initial estimates.
        pose_keys: (R, N) keys of robot r's pose k.
        landmark_keys: landmark subject -> key.
        initial: (R, N, 3) dead-reckoned poses (the initial estimate).
        odometry: (R, N−1, 3) the odometry deltas (to initialise new poses online).
        first_sighting: landmark subject -> (robot row, pose index, range [m], bearing [rad]) of
            the measurement that initialises it.
    """

    factors: list
    values: list
    pose_keys: np.ndarray
    landmark_keys: dict[int, int]
    initial: np.ndarray
    odometry: np.ndarray
    first_sighting: dict[int, tuple[int, int, float, float]]


def nearest_pose(pose_times: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Index of the pose time nearest each time t [s] (ties to the earlier), (len(t),)."""
    j = np.clip(np.searchsorted(pose_times, t), 1, len(pose_times) - 1)
    return np.where(t - pose_times[j - 1] <= pose_times[j] - t, j - 1, j)


def reexpress(rng_bearing: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """Range-bearing measurements (M, 2) taken at poses ``delta`` (M, 3) relative to a reference
    pose, as range-bearing (M, 2) from the reference pose (x forward, y left, bearing CCW)."""
    r, b = rng_bearing[:, 0], rng_bearing[:, 1]
    p = compose(delta, np.column_stack([r * np.cos(b), r * np.sin(b), np.zeros_like(r)]))
    return np.column_stack([np.hypot(p[:, 0], p[:, 1]), np.arctan2(p[:, 1], p[:, 0])])


def build_graph(
    pose_times: np.ndarray,
    robot_ids: tuple[int, ...],
    starts: np.ndarray,
    odometry: np.ndarray,
    odometry_cov: np.ndarray,
    measurements: np.ndarray,
    landmark_cov: np.ndarray,
    sighting_cov: np.ndarray,
    huber_k: float | None = HUBER_K,
    known: np.ndarray | None = None,
) -> GraphSteps:
    """The factor graph, split by pose time.

    Args:
        pose_times: (N,) [s], shared by all robots.
        robot_ids: the R robots' subject numbers (a measured subject among them is a sighting).
        starts: (R, 3) start poses (map frame, x [m], y [m], θ [rad]): tight priors on the known
            ones; every robot's dead reckoning (the initial estimate) starts there.
        odometry: (R, N−1, 3) relative motion from pose k to k+1 in pose k's frame.
        odometry_cov: (R, N−1, 3, 3) its covariance in GTSAM's Pose2 tangent order (x, y, θ) of
            the between error (the frame of pose k+1).
        measurements: (M, 5) robot id, time [s], subject, range [m], bearing [rad], already
            expressed from the robot's pose at the nearest pose time.
        landmark_cov, sighting_cov: (2, 2) noise of (bearing [rad], range [m]).
        huber_k: Huber threshold of the measurement loss; None for a plain Gaussian.
        known: (R,) bool, the robots whose start pose is a prior (default all). The others' start
            poses are only where their initial estimate begins: their frame comes from the
            measurements that link them to the known robots.
    """
    import gtsam

    robot_ids = tuple(int(i) for i in robot_ids)
    n_r, n = len(robot_ids), len(pose_times)
    pose_keys = np.array(
        [[gtsam.symbol(chr(ord("a") + r), k) for k in range(n)] for r in range(n_r)], dtype=np.int64
    )
    initial = np.empty((n_r, n, 3))
    initial[:, 0] = starts
    for k in range(1, n):
        initial[:, k] = compose(initial[:, k - 1], odometry[:, k - 1])

    def robust(cov: np.ndarray) -> Any:
        base = gtsam.noiseModel.Gaussian.Covariance(np.asarray(cov, float))
        if huber_k is None:
            return base
        return gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(huber_k), base)

    lm_noise, rr_noise = robust(landmark_cov), robust(sighting_cov)
    prior = gtsam.noiseModel.Diagonal.Sigmas(np.array(PRIOR_SIGMA))
    factors = [gtsam.NonlinearFactorGraph() for _ in range(n)]
    values = [gtsam.Values() for _ in range(n)]
    known = np.ones(n_r, bool) if known is None else np.asarray(known, bool)
    for r in range(n_r):
        values[0].insert(int(pose_keys[r, 0]), gtsam.Pose2(*starts[r]))
        if known[r]:
            factors[0].add(gtsam.PriorFactorPose2(int(pose_keys[r, 0]), gtsam.Pose2(*starts[r]), prior))
        for k in range(1, n):
            values[k].insert(int(pose_keys[r, k]), gtsam.Pose2(*initial[r, k]))
            factors[k].add(gtsam.BetweenFactorPose2(
                int(pose_keys[r, k - 1]), int(pose_keys[r, k]), gtsam.Pose2(*odometry[r, k - 1]),
                gtsam.noiseModel.Gaussian.Covariance(odometry_cov[r, k - 1]),
            ))

    row_of = {i: r for r, i in enumerate(robot_ids)}
    landmark_keys: dict[int, int] = {}
    first: dict[int, tuple[int, int, float, float]] = {}
    meas = measurements[np.argsort(measurements[:, 1], kind="stable")]
    ks = nearest_pose(pose_times, meas[:, 1])
    for (robot, _, subject, rng, bearing), k in zip(meas, ks):
        r, s, k = row_of[int(robot)], int(subject), int(k)
        key = int(pose_keys[r, k])
        if s in row_of:
            factors[k].add(gtsam.BearingRangeFactorPose2(
                key, int(pose_keys[row_of[s], k]), gtsam.Rot2(bearing), rng, rr_noise))
            continue
        if s not in landmark_keys:
            landmark_keys[s] = gtsam.symbol("l", s)
            first[s] = (r, k, float(rng), float(bearing))
            values[k].insert(landmark_keys[s], gtsam.Point2(*_sighted_point(initial[r, k], rng, bearing)))
        factors[k].add(gtsam.BearingRangeFactor2D(key, landmark_keys[s], gtsam.Rot2(bearing), rng, lm_noise))
    return GraphSteps(factors, values, pose_keys, landmark_keys, initial, np.asarray(odometry, float), first)


def _sighted_point(pose: np.ndarray, rng: float, bearing: float) -> np.ndarray:
    """Map-frame point (2,) at range [m] and bearing [rad] from pose (3,)."""
    return compose(pose, np.array([rng * np.cos(bearing), rng * np.sin(bearing), 0.0]))[:2]


def _poses(values: Any, keys: np.ndarray) -> np.ndarray:
    return np.array([[(p := values.atPose2(int(k))).x(), p.y(), p.theta()] for k in keys.ravel()]).reshape(
        *keys.shape, 3
    )


def _landmarks(values: Any, keys: dict[int, int]) -> dict[int, np.ndarray]:
    return {s: np.asarray(values.atPoint2(k), float) for s, k in keys.items()}


def solve_batch(g: GraphSteps) -> dict:
    """Levenberg–Marquardt on the whole graph from dead reckoning.

    Returns:
        {"poses": (R, N, 3), "landmarks": {subject: (2,)}, "iterations", "error0", "error"}
    """
    import gtsam

    graph, init = gtsam.NonlinearFactorGraph(), gtsam.Values()
    for f, v in zip(g.factors, g.values):
        graph.push_back(f)
        init.insert(v)
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(100)
    params.setRelativeErrorTol(1e-10)
    params.setAbsoluteErrorTol(1e-12)
    opt = gtsam.LevenbergMarquardtOptimizer(graph, init, params)
    res = opt.optimize()
    return {
        "poses": _poses(res, g.pose_keys), "landmarks": _landmarks(res, g.landmark_keys),
        "iterations": int(opt.iterations()), "error0": float(graph.error(init)), "error": float(graph.error(res)),
    }


def solve_isam2(g: GraphSteps, every: int = 1) -> dict:
    """iSAM2, one update per ``every`` pose times, in time order.

    Returns:
        {"online": (R, N, 3) each pose as estimated right after the update that added it,
         "poses": (R, N, 3) the final estimate, "landmarks": {subject: (2,)}, "update_ms": (U,)}
    """
    import gtsam

    params = gtsam.ISAM2Params()
    isam = gtsam.ISAM2(params)
    n = len(g.factors)
    online = np.empty((*g.pose_keys.shape, 3))
    update_ms = []
    for a in range(0, n, max(every, 1)):
        b = min(a + max(every, 1), n)
        graph, vals = gtsam.NonlinearFactorGraph(), gtsam.Values()
        for k in range(a, b):
            graph.push_back(g.factors[k])
            # new poses start from the current estimate ⊕ odometry, not from dead reckoning
            online[:, k] = g.initial[:, 0] if k == 0 else compose(online[:, k - 1], g.odometry[:, k - 1])
            for r, key in enumerate(g.pose_keys[:, k]):
                vals.insert(int(key), gtsam.Pose2(*online[r, k]))
        for s, (r, k, rng, bearing) in g.first_sighting.items():
            if a <= k < b:
                vals.insert(g.landmark_keys[s], gtsam.Point2(*_sighted_point(online[r, k], rng, bearing)))
        t = time.perf_counter()
        isam.update(graph, vals)
        update_ms.append((time.perf_counter() - t) * 1e3)
        for r, k in np.ndindex(g.pose_keys.shape[0], b - a):
            p = isam.calculateEstimatePose2(int(g.pose_keys[r, a + k]))
            online[r, a + k] = p.x(), p.y(), p.theta()
    res = isam.calculateEstimate()
    return {
        "online": online, "poses": _poses(res, g.pose_keys), "landmarks": _landmarks(res, g.landmark_keys),
        "update_ms": np.array(update_ms),
    }


def odometry_covariance(delta: np.ndarray, dt: float, cfg: MrclamConfig) -> np.ndarray:
    """(3, 3) covariance of a relative motion ``delta`` over dt [s] under the filter's motion model,
    rotated from the start pose's frame into the end pose's (GTSAM's Pose2 between error).

    A still robot's interval (no motion in its odometry) has no motion noise in the filter's
    model; here it is held to :data:`PRIOR_SIGMA`, as tight as the start poses, because iSAM2
    cannot factor a between-factor of zero covariance.
    """
    if not reports_motion(delta):
        return np.diag(np.square(PRIOR_SIGMA))
    cov = predict_motion(np.zeros((1, 3)), delta, cfg.filter.motion, dt)[1][0]
    c, s = np.cos(delta[2]), np.sin(delta[2])
    rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    return rot @ cov @ rot.T


def mrclam_inputs(ds: MrclamDataset, cfg: MrclamConfig) -> dict:
    """The filter pipeline's data as :func:`build_graph` arguments (plus "odom": integrators)."""
    ds = ds.calibrated(cfg.calibration)
    t0, t1 = ds.time_span()
    if cfg.duration is not None:
        t1 = min(t1, t0 + cfg.duration)
    times = t0 + cfg.team_step * np.arange(int(np.floor((t1 - t0) / cfg.team_step)) + 1)
    odo = {i: OdometryIntegrator(ds.robots[i].odometry, cfg.odometry_delay) for i in cfg.numbers}
    delta = np.array([[odo[i].delta(a, b) for a, b in zip(times[:-1], times[1:])] for i in cfg.numbers])
    cov = np.array([
        [odometry_covariance(d, b - a, cfg) for d, a, b in zip(dr, times[:-1], times[1:])] for dr in delta
    ])
    rows = []
    for i in cfg.numbers:
        m = ds.robots[i].measurements
        m = m[(m[:, 0] > t0) & (m[:, 0] <= times[-1])]
        if not cfg.use_sightings:
            m = m[m[:, 1] > ds.num_robots]
        m = m[(m[:, 1] > ds.num_robots) | np.isin(m[:, 1], cfg.numbers)]
        # one reading per (stamp, subject), the last one in the file, as the filter keeps
        _, last = np.unique(m[::-1, :2], axis=0, return_index=True)
        m = m[::-1][last]
        k = nearest_pose(times, m[:, 0])
        rel = np.array([odo[i].delta(a, b) for a, b in zip(times[k], m[:, 0])]).reshape(-1, 3)
        rb = reexpress(m[:, 2:4], rel)
        rows.append(np.column_stack([np.full(len(m), i), m[:, 0], m[:, 1], rb]))
    return {
        "pose_times": times,
        "robot_ids": tuple(cfg.numbers),
        "starts": np.array([ds.groundtruth(i, times[:1])[0] for i in cfg.numbers]),
        "odometry": delta,
        "odometry_cov": cov,
        "measurements": np.concatenate(rows),
        "landmark_cov": np.diag([cfg.sigma_bearing**2, cfg.sigma_range**2]),
        "sighting_cov": np.diag([cfg.sigma_sighting_bearing**2, cfg.sigma_sighting_range**2]),
    }


def _ate_row(poses: np.ndarray, gt: np.ndarray) -> list[float]:
    return [ate_rmse(p, g) for p, g in zip(poses, gt)]


def _team_frame(poses: np.ndarray, gt: np.ndarray) -> dict:
    """Per-robot ATE [m] after one rigid transform fitted to the whole team (poses, gt: (R, N, 3)),
    and that transform's rotation [°]: the error of the common frame, removed (as
    ``fusion_mrclam``'s team-aligned figures)."""
    names = [str(r) for r in range(len(poses))]
    ate, t = gauge_free(dict(zip(names, poses)), dict(zip(names, gt)), dict.fromkeys(names, 0))
    return {"team_aligned_ate": [ate[r] for r in names], "team_rotation_deg": float(np.degrees(t[2]))}


def _landmark_error(est: dict[int, np.ndarray], truth: np.ndarray) -> dict[str, float]:
    """Position error of each mapped landmark against its ground truth (by subject) [m]."""
    d = np.array([np.linalg.norm(est[int(s)] - truth[truth[:, 0] == s, 1:3][0]) for s in truth[:, 0] if int(s) in est])
    if d.size == 0:
        return {"landmarks": 0, "landmark_rmse_m": float("nan"), "landmark_max_m": float("nan")}
    return {"landmarks": int(d.size), "landmark_rmse_m": float(np.sqrt(np.mean(d * d))), "landmark_max_m": float(d.max())}


def _filter_row(path: str) -> tuple[list[float], str]:
    """Per-robot ATE of a ``mrslam mrclam`` run (its folder or report.json) and a note on its run."""
    p = Path(path)
    report = json.loads((p / "report.json" if p.is_dir() else p).read_text())
    ates = [r["ate_rmse_m"] for _, r in sorted(report["robots"].items())]
    cfg = report.get("config", {})
    note = (f"M = {cfg.get('filter', {}).get('num_particles', '?')}, mode {cfg.get('mode', '?')}, "
            f"duration {cfg.get('duration')} s, seed {cfg.get('filter', {}).get('seed', '?')}")
    return ates, note


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="mrslam experiment baseline_gtsam", description=__doc__)
    ap.add_argument("folder", help="MR.CLAM dataset folder, e.g. ../shared/data/mrclam/dataset6")
    ap.add_argument("--out", default="runs/experiments")
    ap.add_argument("--period", type=float, help="seconds between poses (default: the filter's step period)")
    ap.add_argument("--seconds", type=float, help="use the first S seconds of the dataset")
    ap.add_argument("--no-isam", action="store_true", help="batch Levenberg–Marquardt only")
    ap.add_argument("--isam-every", type=int, default=1, help="pose times per iSAM2 update (default 1)")
    ap.add_argument("--no-sightings", action="store_true", help="leave robot-to-robot measurements out")
    ap.add_argument("--filter-report", help="a `mrslam mrclam` run folder (or its report.json) to compare with")
    ap.add_argument("--known", type=int, nargs="+", metavar="ROBOT",
                    help="robots whose start pose is a prior (default all); batch LM only when not all")
    args = ap.parse_args(argv)
    try:
        import gtsam  # noqa: F401
    except ImportError:
        print("mrslam experiment baseline_gtsam: gtsam is not installed (pip install .[baselines])")
        return 2
    cfg = MrclamConfig()
    changes: dict[str, Any] = {"duration": args.seconds}
    if args.period:
        changes["team_step"] = args.period
    if args.no_sightings:
        changes["use_sightings"] = False
    cfg = replace(cfg, **changes)
    ds = MrclamDataset(args.folder)
    t = time.perf_counter()
    inputs = mrclam_inputs(ds, cfg)
    known_ids = cfg.numbers if args.known is None else tuple(args.known)
    if not set(known_ids) <= set(cfg.numbers):
        ap.error(f"--known: robots must be among {list(cfg.numbers)}, got {list(known_ids)}")
    known = np.isin(cfg.numbers, known_ids)
    graph = build_graph(**inputs, known=known)
    build_s = time.perf_counter() - t
    times = inputs["pose_times"]
    gt = np.array([ds.groundtruth(i, times) for i in cfg.numbers])
    n_meas = len(inputs["measurements"])
    n_sight = int(np.isin(inputs["measurements"][:, 2], cfg.numbers).sum())
    print(f"MR.CLAM {args.folder}: {len(cfg.numbers)} robots × {len(times)} poses every {cfg.team_step:g} s "
          f"({times[-1] - times[0]:.0f} s), {n_meas} measurements ({n_sight} sightings), "
          f"{len(graph.landmark_keys)} landmarks; graph built in {build_s:.1f} s", flush=True)

    rows: dict[str, dict] = {"dead reckoning": {"ate": _ate_row(graph.initial, gt), "time_s": None}}
    t = time.perf_counter()
    batch = solve_batch(graph)
    rows["batch LM"] = {
        "ate": _ate_row(batch["poses"], gt), "time_s": time.perf_counter() - t,
        **_landmark_error(batch["landmarks"], ds.landmarks), "iterations": batch["iterations"],
        **_team_frame(batch["poses"], gt),
    }
    print(f"  batch LM: {rows['batch LM']['time_s']:.1f} s, {batch['iterations']} iterations", flush=True)
    if not args.no_isam and not known.all():
        print("  iSAM2 not run: a robot without a start prior has no estimate until measurements link it")
    elif not args.no_isam:
        t = time.perf_counter()
        isam = solve_isam2(graph, args.isam_every)
        isam_s = time.perf_counter() - t
        lm = _landmark_error(isam["landmarks"], ds.landmarks)
        u = isam["update_ms"]
        rows["iSAM2 online"] = {"ate": _ate_row(isam["online"], gt), "time_s": isam_s,
                                "update_ms_p50": float(np.median(u)), "update_ms_max": float(u.max())}
        rows["iSAM2 final"] = {"ate": _ate_row(isam["poses"], gt), "time_s": isam_s, **lm}
        print(f"  iSAM2: {isam_s:.1f} s, update p50 {np.median(u):.1f} ms max {u.max():.0f} ms", flush=True)
    note = ""
    if args.filter_report:
        ates, note = _filter_row(args.filter_report)
        rows["filter (report.json)"] = {"ate": ates, "time_s": None}

    names = [f"robot {i}" for i in cfg.numbers]
    lines = [
        f"GTSAM baseline, MR.CLAM {args.folder}, first {times[-1] - times[0]:.0f} s, poses every "
        f"{cfg.team_step:g} s, start poses known: robots {' '.join(str(i) for i in known_ids)}, "
        f"iSAM2 update every {args.isam_every} pose time(s); ATE RMSE [m] against Vicon "
        "at the pose times, no alignment; landmarks: position error against Landmark_Groundtruth, RMSE (max)",
        "",
        "| method | " + " | ".join(names) + " | mean | landmarks [m] | time [s] |",
        "|---" * (len(names) + 4) + "|",
    ]
    for name, r in rows.items():
        lm = f"{r['landmark_rmse_m']:.3f} ({r['landmark_max_m']:.3f})" if "landmark_rmse_m" in r else "–"
        ts = f"{r['time_s']:.1f}" if r["time_s"] is not None else "–"
        lines.append(f"| {name} | " + " | ".join(f"{a:.3f}" for a in r["ate"])
                     + f" | {np.mean(r['ate']):.3f} | {lm} | {ts} |")
    tb = rows["batch LM"]
    lines += ["", "batch LM after one rigid transform fitted to the whole team (the common frame's error "
              f"removed; rotation {tb['team_rotation_deg']:.1f}°): "
              + " / ".join(f"{a:.3f}" for a in tb["team_aligned_ate"]) + " m"]
    if note:
        lines += ["", f"filter row: {args.filter_report} ({note})"]
    lines += ["", "iSAM2 online = each pose's estimate right after the update that added it (causal); "
              "iSAM2 final = the smoothed estimate at the end; time of iSAM2 = all updates."]
    data = {"dataset": str(args.folder), "period_s": cfg.team_step, "seconds": float(times[-1] - times[0]),
            "known": [int(i) for i in known_ids],
            "isam_every": args.isam_every, "build_s": build_s, "measurements": n_meas, "sightings": n_sight,
            "robots": names, "rows": rows}
    write_tables(args.out, "baseline_gtsam", "\n".join(lines), data)
    return 0
