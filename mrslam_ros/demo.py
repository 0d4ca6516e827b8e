"""``mrslam demo``: a simulated team, closed loop, as separate ROS 2 processes talking over DDS.

Starts the simulator node (pybullet, /clock), one stereo frontend per robot (namespace /robotN),
the central SLAM node and the exploration node (which also runs every robot's path follower),
all on simulated time; records a rosbag2 of the run from this process (odometry, ground truth,
observations, scans, estimates, commands, /map, /tf, /diagnostics; images with
``--record-images``); stops everything after ``--seconds`` of simulated time; and writes the run
folder: ``report.json`` (ATE/RPE per robot against the simulator's ground truth, the central
node's step latency, drops, explored share), ``trajectories/*.tum``, plots, ``config.yaml``,
``slam.yaml`` (the central node's parameters, which ``mrslam replay --offline`` reads), ``bag/``
and ``logs/`` (one log per node). With ``--view`` the view node serves the team live to the Foxglove
app (:mod:`mrslam_ros.view_node`).

The parameters of every node come from one :class:`DemoConfig`, whose ``team`` part is the same
:class:`mrslam_core.pipelines.team.TeamConfig` the one-process ``mrslam team`` runs.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal

import numpy as np

from mrslam_core.configio import ConfigError, load_yaml, positive_int, to_dict, write_yaml
from mrslam_core.pipelines.team import TeamConfig
from mrslam_ros.launch import add_view_arguments, view_spec

RECORDED = ("odom", "ground_truth", "observations", "scan", "pose", "cmd_vel", "goal",
            "stereo/left/camera_info", "stereo/right/camera_info")
IMAGES = ("stereo/left/image_raw", "stereo/right/image_raw")


@dataclass(frozen=True)
class Fault:
    """A fault injected into a demo run (the reliability tests use them).

    Attributes:
        at: simulated time of the fault [s].
        node: the node's launch label (``slam``, ``explore``, ``robot2/frontend``, ...).
        action: ``kill``: SIGKILL, then started again ``duration`` simulated seconds later (the
            central node with ``--resume``, from its checkpoint); ``pause``: SIGSTOP, then SIGCONT
            ``duration`` simulated seconds later (a robot whose link is down).
        duration: simulated seconds until the node is restarted or continued [s].
    """

    at: float
    node: str
    action: Literal["kill", "pause"] = "kill"
    duration: float = 0.0


@dataclass(frozen=True)
class DemoConfig:
    """The multi-process demo.

    Attributes:
        real_time_factor: simulated seconds per wall second of the simulator node (lower it when
            the frontends cannot keep up on a slow machine; at 0.7, 3 robots use about 1.35 of
            2 cores and every stereo pair reaches the filter).
        max_wait: how long the central node waits for a late robot's observations [s]; a frontend
            that falls further behind the others than this reorders the filter's updates.
        start_delay: wall seconds the simulator waits, once every frontend is subscribed, before
            time starts (the recorder and the central node discover the graph meanwhile) [s].
        record_images: also record the stereo images (large: about 2.3 MB/s for 3 robots).
        storage: bag storage, "sqlite3" or "mcap".
        startup_timeout: wall seconds allowed until simulated time starts [s].
        checkpoint_period: wall seconds between the central node's checkpoints [s].
        faults: faults to inject, in any order.
        node_prefix: per node label, command words before its interpreter, e.g.
            ``{sim: [ip, netns, exec, robots]}`` to run the robots' side on another (network) host.
        team: team size, duration, world, frontend, filter, exploration, unknown starts (shared
            with ``mrslam team``).
    """

    real_time_factor: float = 0.7
    max_wait: float = 3.0
    start_delay: float = 3.0
    record_images: bool = False
    storage: str = "sqlite3"
    startup_timeout: float = 60.0
    checkpoint_period: float = 5.0
    faults: tuple[Fault, ...] = ()
    node_prefix: dict[str, tuple[str, ...]] = field(default_factory=dict)
    team: TeamConfig = field(default_factory=TeamConfig)


def world_facts(cfg: TeamConfig) -> dict:
    """Start poses, camera mount and reachable free cells of the simulated world (no rendering)."""
    from mrslam_core.sim.simulation import Simulation

    sim = Simulation(cfg.sim)
    try:
        names = [f"robot{i + 1}" for i in range(cfg.robots)]
        for n in names:
            sim.add_robot(n)
        return {
            "names": names,
            "starts": np.array([sim.ground_truth(n) for n in names]),
            "t_base_cam": sim.camera_extrinsic(),
            "truth_free": sim.world.reachable_free(cfg.grid.resolution),
        }
    finally:
        sim.close()


def slam_params(cfg: DemoConfig, facts: dict, out: Path):
    """The central node's config (a :class:`SlamNodeConfig`)."""
    from mrslam_ros.slam_node import SlamNodeConfig

    return SlamNodeConfig(robots=tuple(facts["names"]), start_poses=tuple(float(v) for v in facts["starts"].ravel()),
                          max_wait=cfg.max_wait, filter=cfg.team.filter, map_check=cfg.team.map_check,
                          unknown_start=cfg.team.unknown_start, rendezvous=cfg.team.rendezvous, fusion=cfg.team.fusion,
                          odometry=(cfg.team.odometry,), wheel_motion=cfg.team.filter.motion,
                          output_dir=str(out / "slam"),
                          checkpoint=str(out / "slam" / "checkpoint.npz"), checkpoint_period=cfg.checkpoint_period)


def launch_config(cfg: DemoConfig, facts: dict, out: Path, view=None):
    """The node processes of the demo (``view``: the view node's spec, or None)."""
    from mrslam_ros.launch import LaunchConfig, NodeSpec

    team = cfg.team
    names = facts["names"]
    nodes = [NodeSpec(module="mrslam_ros.sim_node", name="sim", use_sim_time=False,
                      params={"robots": team.robots, "real_time_factor": cfg.real_time_factor, "sim": to_dict(team.sim),
                              "fiducials": to_dict(team.fiducials), "wait_for_frontends": True,
                              "start_delay": cfg.start_delay})]
    t_base_cam = [float(v) for v in np.asarray(facts["t_base_cam"]).ravel()]
    for n in names:
        nodes.append(NodeSpec(module="mrslam_ros.frontend_node", name="frontend", namespace=n,
                              params={"robot": n, "t_base_cam": t_base_cam, "frontend": to_dict(team.frontend),
                                      "fiducials": to_dict(team.fiducials)}))
    nodes.append(NodeSpec(module="mrslam_ros.slam_node", name="slam", params=to_dict(slam_params(cfg, facts, out))))
    nodes.append(NodeSpec(module="mrslam_ros.explore_node", name="explore",
                          params={"robots": list(names), "control_period": team.control_period,
                                  "exploration": to_dict(team.exploration), "control": to_dict(team.control),
                                  "grid": to_dict(team.grid)}))
    if view is not None:
        nodes.append(replace(view, params={**view.params, "robots": list(names)}))
    unknown = set(cfg.node_prefix) - {n.label for n in nodes}
    if unknown:
        raise ConfigError(f"node_prefix: no nodes {sorted(unknown)} (have {[n.label for n in nodes]})")
    nodes = [replace(n, prefix=list(cfg.node_prefix.get(n.label, ()))) for n in nodes]
    if any(f.action == "kill" for f in cfg.faults) and "FASTDDS_BUILTIN_TRANSPORTS" not in os.environ:
        # A SIGKILLed Fast DDS participant leaves its shared-memory port behind; a process started
        # in its place can match every topic and still receive nothing over shared memory
        # (eProsima/Fast-DDS#2811, #5053; a CI run's restarted frontend published nothing for
        # 29 s). Announcing UDP locators only makes the publishers use the loopback network.
        nodes = [replace(n, env={**n.env, "FASTDDS_BUILTIN_TRANSPORTS": "UDPv4"}) for n in nodes]
    return LaunchConfig(use_sim_time=True, log_dir=str(out / "logs"), stop_timeout=10.0, nodes=nodes)


def run(cfg: DemoConfig, out: Path, log=sys.stdout, view=None) -> dict:
    """Run the team, record it, stop it; returns what the report needs (``view``: the view
    node's spec, or None)."""
    import rclpy
    from rclpy.experimental import EventsExecutor
    from rclpy.parameter import Parameter

    from mrslam_ros.bag import BagRecorder
    from mrslam_ros.launch import Launcher

    facts = world_facts(cfg.team)
    out.mkdir(parents=True, exist_ok=True)
    write_yaml(slam_params(cfg, facts, out), out / "slam.yaml")
    bag = out / "bag"
    if bag.exists():
        raise FileExistsError(f"{bag} exists: choose another --out or remove it")
    topics = ["/clock", "/tf", "/map", "/diagnostics"]
    for n in facts["names"]:
        topics += [f"/{n}/{t}" for t in RECORDED + (IMAGES if cfg.record_images else ())]
    launcher = Launcher(launch_config(cfg, facts, out, view), log=open(out / "nodes.log", "w"))
    rclpy.init(args=[])
    node = rclpy.create_node("mrslam_demo", parameter_overrides=[Parameter("use_sim_time", value=True)])
    recorder = BagRecorder(node, bag, topics, cfg.storage)
    # rclpy's C++ events executor: the Python one rebuilds its wait set of the ~40 recorded topics
    # for every message, about 3 ms a message at the demo's 200 a second (a 30 s demo: the
    # launcher's CPU 31 -> 15 s, the same messages in the bag).
    executor = EventsExecutor()
    executor.add_node(node)
    end_ns = int(cfg.team.seconds * 1e9)
    wall0 = time.monotonic()
    failed: list[str] = []
    cpu: dict[str, float] = {}
    try:
        launcher.start()
        print(f"demo: started {len(launcher.procs)} node processes; logs in {out / 'logs'}", file=log, flush=True)
        next_report = 10e9
        pending = sorted(cfg.faults, key=lambda f: f.at)
        recover: list[tuple[float, Fault]] = []
        down: set[str] = set()
        injected = []
        while True:
            executor.spin_once(timeout_sec=0.05)
            now = node.get_clock().now().nanoseconds
            if now >= end_ns:
                break
            while pending and now >= pending[0].at * 1e9:
                f = pending.pop(0)
                launcher.send_signal(f.node, signal.SIGKILL if f.action == "kill" else signal.SIGSTOP)
                down.add(f.node)
                recover.append((f.at + f.duration, f))
                injected.append({"fault": f.action, "node": f.node, "at_s": now * 1e-9, "wall_s": time.monotonic() - wall0})
                print(f"demo: t = {now * 1e-9:.1f} s: {f.action} {f.node}", file=log, flush=True)
            for item in [r for r in recover if now >= r[0] * 1e9]:
                recover.remove(item)
                f = item[1]
                if f.action == "kill":
                    launcher.restart(f.node, ["--resume"] if f.node == "slam" else None)
                else:
                    launcher.send_signal(f.node, signal.SIGCONT)
                down.discard(f.node)
                injected.append({"recover": f.action, "node": f.node, "at_s": now * 1e-9, "wall_s": time.monotonic() - wall0})
                print(f"demo: t = {now * 1e-9:.1f} s: {f.node} back", file=log, flush=True)
            failed = [label for label in launcher.failed() if label not in down]
            if failed:
                print(f"demo: node(s) {failed} exited early; stopping", file=log, flush=True)
                break
            if now == 0 and time.monotonic() - wall0 > cfg.startup_timeout:
                failed = ["sim (no /clock)"]
                print(f"demo: no /clock after {cfg.startup_timeout:.0f} s; stopping", file=log, flush=True)
                break
            if now >= next_report:
                print(f"demo: t = {now * 1e-9:5.0f} s (wall {time.monotonic() - wall0:5.0f} s)", file=log, flush=True)
                next_report += 10e9
        for _, f in recover:  # faults still active at the end: undo them so the nodes stop cleanly
            launcher.send_signal(f.node, signal.SIGCONT)
        cpu = launcher.cpu_seconds()
    finally:
        codes = launcher.stop()
        recorder.close()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return {"facts": facts, "bag": bag, "exit_codes": codes, "failed": failed, "faults": injected,
            "wall_s": time.monotonic() - wall0, "counts": dict(recorder.counts), "cpu_s": cpu}


def write_report(cfg: DemoConfig, out: Path, facts: dict, extra: dict | None = None,
                 est: dict | None = None, slam_stats: dict | None = None, map_npz: Path | None = None) -> dict:
    """The run folder from the bag (estimates from ``/<robot>/pose`` unless ``est`` is given)."""
    from mrslam_core.evaluation.report import write_run
    from mrslam_core.exploration.coverage import explored_fraction
    from mrslam_ros.conversions import occupancy_to_arrays
    from mrslam_ros.runlog import diagnostics, evaluation_trajectories, last_message, read_series

    bag = out / "bag"
    names = facts["names"]
    series = read_series(bag, names)
    if est is None:
        est = {r: series[r]["pose"].arrays() for r in names}
    starts = {r: facts["starts"][i] for i, r in enumerate(names)}
    trajectories = evaluation_trajectories(est, series, starts)
    explored = occupancy = None
    grid = last_message(bag, "/map")
    if grid is not None:
        prob, known, origin, res = occupancy_to_arrays(grid)
        explored = explored_fraction(known, origin, res, facts["truth_free"], cfg.team.grid.resolution)
        occupancy = {"probability": prob, "known": known, "origin": origin, "resolution": res,
                     "free_thresh": cfg.team.grid.free_below, "occupied_thresh": cfg.team.grid.occupied_above}
    slam_stats = slam_stats or {}
    landmarks = None
    if map_npz is not None and map_npz.is_file():
        with np.load(map_npz) as z:
            landmarks = {"mean": z["mean"], "cov": z["cov"]}
    info = {"explored_fraction": explored, "dropped": slam_stats.get("dropped", {}),
            "latency_ms": slam_stats.get("latency_ms"),
            "diagnostics": diagnostics(bag), "updates": slam_stats.get("updates", {}),
            "outlier_matches": slam_stats.get("outlier_matches"), "map_checks": slam_stats.get("map_checks"),
            "relocalizations": slam_stats.get("relocalizations"), "merges": slam_stats.get("merges")}
    info.update(extra or {})
    return write_run(out, trajectories, cfg, np.asarray(slam_stats.get("update_ms_all", []), float), landmarks,
                     extra=info, occupancy=occupancy)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="mrslam demo", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", help="YAML with DemoConfig keys (team: TeamConfig keys)")
    ap.add_argument("--robots", type=positive_int, help="team size")
    ap.add_argument("--seconds", type=float, help="simulated duration [s]")
    ap.add_argument("--world", help="simulated world (office, small)")
    ap.add_argument("--rtf", type=float, help="real-time factor of the simulator")
    ap.add_argument("--record-images", action="store_true", help="also record the stereo images")
    ap.add_argument("--out", default="runs/demo", help="run folder (default runs/demo)")
    add_view_arguments(ap)
    args = ap.parse_args(argv)
    try:
        cfg = load_yaml(DemoConfig, args.config) if args.config else DemoConfig()
    except ConfigError as exc:
        print(f"mrslam demo: {exc}", file=sys.stderr)
        return 2
    team = cfg.team
    if args.robots:
        team = replace(team, robots=args.robots)
    if args.seconds:
        team = replace(team, seconds=args.seconds)
    if args.world:
        team = replace(team, sim=replace(team.sim, world=args.world))
    cfg = replace(cfg, team=team, record_images=cfg.record_images or args.record_images,
                  real_time_factor=args.rtf or cfg.real_time_factor)
    out = Path(args.out)
    print(f"mrslam demo: {team.robots} robots, {team.seconds:.0f} s in world {team.sim.world}, "
          f"real-time factor {cfg.real_time_factor:g}; writing {out}", flush=True)
    try:
        res = run(cfg, out, view=view_spec(args) if args.view else None)
    except (FileExistsError, ConfigError) as exc:
        print(f"mrslam demo: {exc}", file=sys.stderr)
        return 2
    stats_file = out / "slam" / "slam.json"
    stats = json.loads(stats_file.read_text()) if stats_file.is_file() else {}
    if not stats:
        print(f"mrslam demo: the central node wrote no {stats_file}", file=sys.stderr)
    report = write_report(cfg, out, res["facts"], slam_stats=stats, map_npz=out / "slam" / "map.npz",
                          extra={"wall_s": res["wall_s"], "exit_codes": res["exit_codes"],
                                 "bag_messages": res["counts"], "failed_nodes": res["failed"], "faults": res["faults"],
                                 "cpu_s": res["cpu_s"]})
    for name, r in report["robots"].items():
        if "ate_rmse_m" in r:
            print(f"  {name}: ATE {r['ate_rmse_m']:.3f} m (odometry {r['odom_ate_rmse_m']:.3f} m), "
                  f"RPE {r['rpe_rmse_m']:.3f} m, {r['poses']} poses")
    u = report["update_ms"]
    explored = report["explored_fraction"]
    drops = ", ".join(f"{k} {v}" for k, v in sorted(report["dropped"].items()) if v) or "none"
    print(f"  landmarks {report['landmarks']}; explored {'n/a' if explored is None else f'{explored:.0%}'}; "
          f"central step p50 {u['p50']:.1f} p95 {u['p95']:.1f} max {u['max']:.1f} ms; drops: {drops}; "
          f"wall {res['wall_s']:.0f} s")
    if "view" in res["cpu_s"]:
        others = sum(v for k, v in res["cpu_s"].items() if k != "view")
        print(f"  view node: {res['cpu_s']['view']:.1f} s CPU, {res['cpu_s']['view'] / max(others, 1e-9):.1%} of the "
              f"other nodes' {others:.0f} s")
    print(f"report: {out / 'report.json'}")
    return 1 if res["failed"] else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
