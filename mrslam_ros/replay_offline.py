"""``mrslam replay BAG --offline``: feed a recorded run straight into the central mapper, as fast as
possible, and write the same run folder as the live run.

The bag's ``/<robot>/odom`` (or ``/<robot>/visual_odom``, or both fused, as the central node's
``odometry`` sources say) and ``/<robot>/observations`` go, in the order they were recorded,
into :class:`mrslam_core.pipelines.central.CentralMapper` configured from the central node's
parameters (``--config``, default ``slam.yaml`` beside the bag, as ``mrslam demo`` writes it), so
the filter makes the same updates in the same order as the live node did; the report compares
the estimates with ``/<robot>/ground_truth`` and the odometry, and (``--compare``, on by default
when the bag holds ``/<robot>/pose``) with the live node's estimates.

``--seed`` replaces the filter's seed (one recording, many draws of the filter). ``--downtime A:B``
replays a central node killed after its checkpoint at A s and back with ``--resume`` at B s: the
mapper is saved once it has every message stamped up to A, resumed from that checkpoint, and sees
nothing stamped before B (what a live node misses while it is down).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

from mrslam_core.configio import ConfigError, load_yaml
from mrslam_core.evaluation.metrics import interpolate_poses
from mrslam_core.evaluation.report import write_run
from mrslam_core.pipelines.central import CentralMapper
from mrslam_ros.bag import BagError, bag_info, read_bag


def feed(bag: Path, mapper: CentralMapper, progress: bool = True,
         downtime: tuple[float, float] | None = None) -> tuple[dict[str, int], CentralMapper]:
    """Feed the bag's odometry and observation sets into ``mapper``.

    Args:
        downtime: (checkpoint, back) [s of stamp time]: the mapper is saved once every message
            stamped up to ``checkpoint`` is in, resumed from the save, and given nothing stamped
            before ``back`` (a central node killed and restarted with ``--resume``).

    Returns:
        messages used per kind, and the mapper at the end (a new one after a downtime).
    """
    import tempfile

    from mrslam_ros.conversions import ConversionError, cloud_to_observations, odometry_to_pose
    from mrslam_ros.runlog import deserialize

    down = None if downtime is None else (int(downtime[0] * 1e9), int(downtime[1] * 1e9))
    skip_until = 0

    from mrslam_core.pipelines.odometry import OdometrySource
    from mrslam_ros.conversions import odometry_twist_covariance

    source = getattr(mapper.cfg, "source", lambda r: "wheel")  # the central node's odometry sources
    odometry = {r: OdometrySource(source(r), mapper.cfg.wheel_motion) for r in mapper.robots}
    topics = {}
    for r in mapper.robots:
        if odometry[r].uses_wheel:
            topics[f"/{r}/odom"] = (r, "odom")
        if odometry[r].uses_visual:
            topics[f"/{r}/visual_odom"] = (r, "visual_odom")
        topics[f"/{r}/observations"] = (r, "obs")
    info = bag_info(bag)
    total = sum(t.count for name, t in info.topics.items() if name in topics)
    used = {"odom": 0, "obs": 0, "bad": 0}
    t0 = time.monotonic()
    for i, m in enumerate(read_bag(bag, topics)):
        robot, kind = topics[m.topic]
        msg = deserialize(m.data, m.msgtype)
        try:
            if kind in ("odom", "visual_odom"):
                stamp, pose, _ = odometry_to_pose(msg)
                twist_cov = odometry_twist_covariance(msg) if kind == "visual_odom" else None
            else:
                obs = cloud_to_observations(msg, robot)
                stamp = obs.stamp_ns
        except ConversionError:
            used["bad"] += 1
            continue
        if down is not None and stamp > down[0]:
            mapper.process(flush=True)
            with tempfile.TemporaryDirectory() as tmp:
                mapper = CentralMapper.resume(mapper.cfg, mapper.save(Path(tmp) / "checkpoint.npz"))
            skip_until, down = down[1], None
        if stamp < skip_until:
            continue
        if kind in ("odom", "visual_odom"):
            src = odometry[robot]
            poses = src.wheel(stamp, pose) if kind == "odom" else src.visual(stamp, pose, twist_cov)
            for t, p in poses:
                mapper.add_odometry(robot, t, p)
            kind = "odom"
        else:
            mapper.add_observations(obs)
            mapper.process()
        used[kind] += 1
        if progress and (i % 200 == 0 or i + 1 == total):
            done = (i + 1) / max(total, 1)
            bar = "#" * int(30 * done)
            rate = (i + 1) / max(time.monotonic() - t0, 1e-9)
            print(f"\r  [{bar:<30}] {100 * done:5.1f} %  {rate:6.0f} msg/s", end="", file=sys.stderr, flush=True)
    mapper.process(flush=True)
    if progress:
        print(file=sys.stderr)
    return used, mapper


def compare(est: dict[str, tuple[np.ndarray, np.ndarray]], live: dict[str, tuple[np.ndarray, np.ndarray]]) -> dict:
    """Per robot, position difference between two estimate series at the first one's stamps [m]."""
    out = {}
    for r, (t, poses) in est.items():
        lt, lp = live.get(r, (np.zeros(0), np.zeros((0, 3))))
        if len(lt) < 2 or not len(t):
            continue
        keep = (t >= lt[0]) & (t <= lt[-1])
        at = interpolate_poses(t[keep].astype(float), lt.astype(float), lp)
        d = np.linalg.norm(poses[keep, :2] - at[:, :2], axis=1)
        out[r] = {"max_m": float(d.max(initial=0.0)), "rmse_m": float(np.sqrt(np.mean(d ** 2))) if d.size else 0.0,
                  "poses": int(d.size), "live_poses": int(len(lt))}
    return out


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="mrslam replay --offline", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("bag")
    ap.add_argument("--offline", action="store_true")
    ap.add_argument("--config", help="central node parameters (SlamNodeConfig YAML); default: slam.yaml beside the bag")
    ap.add_argument("--out", help="run folder (default: <bag>_offline)")
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    ap.add_argument("--seed", type=int, help="the filter's seed instead of the config's")
    ap.add_argument("--downtime", metavar="A:B", help="replay a central node killed after its checkpoint at A s "
                    "and back with --resume at B s (stamp time)")
    args, _ = ap.parse_known_args(argv)
    from mrslam_ros.runlog import evaluation_trajectories, read_series
    from mrslam_ros.slam_node import SlamNodeConfig

    bag = Path(args.bag)
    bag_info(bag)  # BagError (one line) for a path that is not a bag, before looking beside it
    config = Path(args.config) if args.config else bag.resolve().parent / "slam.yaml"
    out = Path(args.out) if args.out else bag.with_name(bag.name + "_offline")
    if not config.is_file():
        raise ConfigError(f"{config}: no such file (the central node's parameters; --config names them)")
    cfg = load_yaml(SlamNodeConfig, config)
    if args.seed is not None:
        cfg = dataclasses.replace(cfg, filter=dataclasses.replace(cfg.filter, seed=args.seed))
    downtime = None
    if args.downtime:
        try:
            downtime = tuple(float(v) for v in args.downtime.split(":"))
            if len(downtime) != 2 or not downtime[0] < downtime[1]:
                raise ValueError
        except ValueError:
            print(f"mrslam replay --offline: --downtime {args.downtime!r}: expected A:B with A < B [s]", file=sys.stderr)
            return 2
    mapper = CentralMapper(cfg)
    wall = time.monotonic()
    try:
        used, mapper = feed(bag, mapper, progress=not args.quiet, downtime=downtime)
        series = read_series(bag, mapper.robots)
    except BagError as exc:
        print(f"mrslam replay --offline: {exc}", file=sys.stderr)
        return 2
    wall = time.monotonic() - wall
    est = mapper.trajectories()
    starts = dict(zip(mapper.robots, np.asarray(cfg.start_poses, float).reshape(-1, 3)))
    trajectories = evaluation_trajectories(est, series, starts)
    live = {r: series[r]["pose"].arrays() for r in mapper.robots}
    slots, mean, cov, _, _ = mapper.slam.best_map()
    report = write_run(out, trajectories, cfg, np.asarray(mapper.update_ms), {"mean": mean, "cov": cov},
                       extra={"dropped": mapper.counters(), "messages": used, "wall_s": wall,
                              "live_difference": compare(est, live),
                              "outlier_matches": mapper.slam.outlier_pairs / mapper.slam.num_particles,
                              "map_checks": dict(mapper.map_checks), "relocalizations": mapper.relocalizations,
                              "merges": mapper.merges, "restarts": mapper.restarts})
    for name, r in report["robots"].items():
        if "ate_rmse_m" in r:
            diff = report["live_difference"].get(name)
            vs = f"; vs live: max {diff['max_m']:.4f} m" if diff else ""
            print(f"  {name}: ATE {r['ate_rmse_m']:.3f} m (odometry {r['odom_ate_rmse_m']:.3f} m), {r['poses']} poses{vs}")
    u = report["update_ms"]
    print(f"  {sum(len(t) for t, _ in est.values())} updates in {wall:.1f} s; step p50 {u['p50']:.1f} p95 {u['p95']:.1f} ms")
    print(f"report: {out / 'report.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
