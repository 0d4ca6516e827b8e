"""A simulated team, closed loop, in one process: simulator -> stereo frontends -> the central
mapper (ONE multi-robot filter, with its map check) -> occupancy grid -> coordinated exploration
-> drive commands.

The same cores the ROS nodes wrap, without a graph: this is the reference the node suite is
measured against and the fastest way to run an experiment. ``mrslam team --out DIR`` writes the
usual run folder (report.json, TUM files, plots, config.yaml).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from mrslam_core.configio import ConfigError, load_yaml
from mrslam_core.evaluation.report import write_run
from mrslam_core.exploration.config import ExplorationConfig, GridConfig
from mrslam_core.exploration.coverage import explored_fraction
from mrslam_core.exploration.explorer import Explorer, State
from mrslam_core.exploration.grid import OccupancyGrid, Scan
from mrslam_core.frontend.camera import StereoRig
from mrslam_core.frontend.config import FrontendConfig
from mrslam_core.frontend.frontend import Frontend
from mrslam_core.frontend.odometry import planar_motion
from mrslam_core.geometry.se2 import between
from mrslam_core.pipelines.central import CentralConfig, CentralMapper, MapCheckConfig
from mrslam_core.sim.config import SimConfig
from mrslam_core.sim.simulation import Simulation
from mrslam_core.slam.config import AssociationConfig, FilterConfig, MotionConfig


def _team_filter() -> FilterConfig:
    # The motion model matches the simulator's default odometry errors (002 Table I): variance
    # 1.25e-3 m²/m per translation component, 5.5e-3 rad²/m and 1.7e-3 rad²/rad of heading;
    # alpha2 covers the heading drift of the wheel-scale difference (0.03 rad/m), var_theta_per_rad
    # the track error. alpha1 = 0: Thrun's alpha1·rot1² gave a robot that moved a few mm sideways
    # (rot1 near ±π/2) 0.2 rad of heading noise in one step, and the joint resampling then walked
    # its heading several degrees while it saw nothing (replays of recorded runs, docs/results.md).
    # E0 = 0.25 instead of 0.5: measured against the rendered truth, 14 % of the associations
    # joined points more than 0.3 m apart with E0 = 0.5 (U-SURF look-alikes on the textures),
    # 6-7 % with 0.25.
    # outlier_gate = chi2(3 dof, 0.99): a look-alike that passes the association gate only because
    # the pose is uncertain is left out of the pose proposal and the map. On recorded live demo
    # runs (4 bags x 8 filter seeds, docs/results.md) robots above 0.15 m went from
    # 43 to 15 of 96; in closed loop (mrslam team, 16 seeds) 16 to 15 of 48.
    # track_gate 30 (chi2(3 dof) at 1 - 1e-6): a frontend track keeps its landmark through an
    # odometry step 3-4 sigma off, where every point of the set fell outside D0 and the set was
    # mapped again at the wrong heading (recorded demo d1, robot1 at 2.3 s: 0 of 12 points
    # associated, heading -4 deg in one step). Closed loop, seeds 0-8: robots above 0.10 m
    # 2 -> 0 of 27; the d1 recording over filter seeds 0-9: target met 0 -> 3 of 10
    # (docs/results.md).
    return FilterConfig(
        num_particles=300,
        proposal="fastslam2",
        motion=MotionConfig(alpha1=0.0, alpha2=0.001, alpha3=0.001, alpha4=0.0, min_translation=0.005,
                            var_xy_per_m=1.25e-3, var_theta_per_m=5.5e-3, var_theta_per_rad=1.75e-3),
        association=AssociationConfig(descriptor_gate=0.25, outlier_gate=11.34, track_gate=30.0),
    )


def _team_exploration() -> ExplorationConfig:
    # Slower than the 2D exploration defaults, for the 5 Hz stereo frontend (measured on the
    # office world, docs/results.md): turning at 1.2 rad/s moves the image 55 px per frame and
    # tracks rarely live the 3 frames an observation needs, and robots that graze obstacles see
    # nothing (the camera's near limit was f·b/max_disparity = 0.43 m, now 0.21 m); such gaps let the particle
    # cloud spread and re-acquire a wrong heading. 0.5 rad/s (23 px per frame), 0.35 m/s and
    # 0.4 m clearance halved the frames without observations (7 % -> 3 %).
    # start_delay 1 s: the robots stand at their known start poses until their first landmarks
    # are mapped (points are published from the 3rd frame, 0.4 s). Driving off at once, the team's
    # first landmarks were mapped from particles already spread by 0.1-0.2 m of odometry, and the
    # heading they fixed for everything mapped later was off by 0.36 deg (median of 27 robots, 9
    # above 0.5 deg); standing, 0.12 deg (none above 0.5). Closed loop, seeds 0-8: target met in
    # 3 -> 7 of 9 runs (docs/results.md).
    # keep_arc: the follower slows down to drive the pure-pursuit arc instead of swinging wide.
    # Closed loop, fresh seeds 14-22 (docs/results.md): target met 7 -> 9 of 9 runs,
    # robots above 0.10 m 2 -> 0 of 27, explored 53 -> 64 %. (Before robots left teammates out
    # of the grid and recovered when boxed in, it cost exploration: a wedge.)
    # open_side_turns: 10 of the 11 blind spells (fewer than 3 points a set for 0.8 s or more)
    # of recorded demos d1 and d3 were turns of 29-212 deg with the camera 0.06-0.14 m from a
    # wall; in the two traced, the robot came out of the turn 3-7 deg off. With keep_arc and the
    # map check's gain gate (same seeds): met 9 of 9, summed ATE 0.122 -> 0.114 m, explored
    # 64 -> 58 %. Without it (keep_arc and the map check only): met 9 of 9, 0.123 m, 65 %: it costs
    # exploration for an accuracy gain within the noise of 9 seeds (docs/results.md).
    # turn_clearance 0.6 m: before a turn on the spot whose headings pass nearer than 0.6 m to an
    # occupied cell, the robot backs straight away (up to 0.4 m, where the space behind is free);
    # the cameras sit 0.12 m ahead of the axle and see nothing nearer than 0.21 m. Closed loop
    # (docs/results.md), seeds 14-27: robots above 0.10 m 2 -> 0 of 42, and the two
    # runs it missed were robots wedged (a turn on the spot against a door jamb, three robots
    # turning into each other), which the reversal of blocked turns (turn_stall_time, on by
    # default) frees; with both, fresh seeds 28-39: met 8 -> 9 of 12, robots above 0.10 m
    # 5 -> 2 of 36.
    # max_turn_rate 0.35 rad/s (16 px per frame): fresh seeds 28-39, met 10 -> 11 of 12, robots
    # above 0.10 m 1 -> 0 of 36, summed ATE 0.156 -> 0.108 m, explored 62 -> 60 % (the miss: a
    # robot at 0.029 m, 32 % of its odometry's 0.09 m); docs/results.md.
    return ExplorationConfig(max_speed=0.35, max_turn_rate=0.35, robot_radius=0.4, start_delay=1.0, keep_arc=True,
                             open_side_turns=True, turn_clearance=0.6)


def _team_frontend() -> FrontendConfig:
    # Renderings have exact calibration. Measured on the office renderings against the depth
    # buffer: disparity error σ 0.24 px (MAD) to 0.36 px (std) on smooth surfaces; Harris corners
    # sit on whole pixels (±0.5 px). σd = 0.5 px and σr = σc = 1 px keep a margin (000 uses
    # 1 and 10 px for a real head with calibration error).
    # max_disparity 128 puts the near limit f·b/d at 0.21 m (64: 0.43 m): a robot facing a wall
    # at the planner's 0.4 m clearance has its cameras 0.28 m from it and saw nothing with 64.
    return FrontendConfig(sigma_d=0.5, sigma_r=1.0, sigma_c=1.0, max_disparity=128)


@dataclass(frozen=True)
class TeamConfig:
    """The simulated team run.

    Attributes:
        robots: team size.
        seconds: simulated duration [s].
        control_period: exploration/drive command period [s].
        explore: send the robots to frontiers (else they stand still).
        map_check: the central mapper's check of each robot against the older map (also the
            demo's central node's).
    """

    robots: int = 3
    seconds: float = 120.0
    control_period: float = 0.2
    explore: bool = True
    sim: SimConfig = field(default_factory=SimConfig)
    frontend: FrontendConfig = field(default_factory=_team_frontend)
    filter: FilterConfig = field(default_factory=_team_filter)
    map_check: MapCheckConfig = field(default_factory=MapCheckConfig)
    exploration: ExplorationConfig = field(default_factory=_team_exploration)
    grid: GridConfig = field(default_factory=GridConfig)


def run(cfg: TeamConfig, progress: bool = False) -> dict:
    """Run the closed loop; returns trajectories, step times, the map and counters."""
    sim = Simulation(cfg.sim)
    names = [f"robot{i + 1}" for i in range(cfg.robots)]
    for n in names:
        sim.add_robot(n)
    starts = np.array([sim.ground_truth(n) for n in names])
    rig = StereoRig(*sim.camera_infos(), sim.camera_extrinsic())
    frontends = {n: Frontend(rig, cfg.frontend, robot=n) for n in names}
    mapper = CentralMapper(CentralConfig(robots=tuple(names), start_poses=tuple(float(v) for v in starts.ravel()),
                                         map_check=cfg.map_check, filter=cfg.filter))
    slam = mapper.slam
    grid = OccupancyGrid(cfg.grid)
    explorer = Explorer(cfg.exploration, names)
    odom0 = {n: sim.odometry(n)[0] for n in names}
    at_frame = dict(odom0)  # each robot's odometry at its previous frame: the frontend's motion prior
    for n in names:
        mapper.add_odometry(n, sim.time_ns, odom0[n])
    rec = {n: {"t": [0.0], "est": [starts[i]], "gt": [starts[i]], "odom": [starts[i]]} for i, n in enumerate(names)}
    next_control = 0
    control_ns = int(cfg.control_period * 1e9)
    end_ns = int(cfg.seconds * 1e9)
    wall = time.perf_counter()
    while sim.time_ns < end_ns:
        sim.step()
        scans = {}
        for n in sim.frames_due():
            frame = sim.render_stereo(n)
            odom = sim.odometry(n)[0]
            delta = between(at_frame[n], odom)
            at_frame[n] = odom
            obs, scan = frontends[n].step(frame.left, frame.right, frame.stamp_ns, odometry=planar_motion(delta))
            mapper.add_odometry(n, frame.stamp_ns, odom)
            if obs is None:  # a dropped frame: the next set carries its motion
                continue
            mapper.add_observations(obs)
            scans[n] = scan
        for done in mapper.process(flush=True):
            if not done.merged:  # awaiting its re-localisation: no map pose to record or to map from
                continue
            n = done.robot
            r = rec[n]
            r["t"].append(done.stamp_ns * 1e-9)
            r["est"].append(done.pose)
            r["gt"].append(sim.ground_truth(n))
            r["odom"].append(_odom_in_map(starts[names.index(n)], odom0[n], done.odom))
            if scans.get(n) is not None:  # the other robots at their newest estimates
                grid.insert(done.pose, Scan.from_obstacle_scan(scans[n]), [rec[o]["est"][-1][:2] for o in names if o != n])
        if cfg.explore and sim.time_ns >= next_control:
            next_control += control_ns
            poses = {n: slam.estimate().mean[slam.index[n]] for n in names}
            for n, (v, w) in explorer.step(grid, poses, sim.time_ns * 1e-9).items():
                sim.set_command(n, v, w)
            if explorer.state is State.COMPLETE:
                break
        if progress and sim.time_ns % int(10e9) == 0:
            print(f"  t = {sim.time_ns * 1e-9:5.0f} s  wall {time.perf_counter() - wall:6.1f} s", file=sys.stderr, flush=True)
    trajectories = {n: {k: np.array(v) for k, v in r.items()} for n, r in rec.items()}
    _, mean, cov, _, _ = slam.best_map()
    truth_free = sim.world.reachable_free(cfg.grid.resolution) if hasattr(sim.world, "reachable_free") else None
    sim.close()
    explored = None
    if truth_free is not None:
        explored = explored_fraction(grid.observed, grid.origin, grid.res, truth_free, cfg.grid.resolution)
    return {
        "trajectories": trajectories, "update_ms": np.array(mapper.update_ms), "landmarks": {"mean": mean, "cov": cov},
        "dropped": dict(slam.dropped) | dict(mapper.drops), "map_checks": dict(mapper.map_checks),
        "relocalizations": mapper.relocalizations, "frontend_drops": {n: dict(f.drops) for n, f in frontends.items()},
        "explored_fraction": explored, "exploration_state": explorer.state.value, "stalls": explorer.stalls, "held": explorer.held,
        "boxed_in": explorer.boxed_in, "long_turns": explorer.long_turns,
        "turn_backoffs": explorer.turn_backoffs, "blocked_turns": explorer.blocked_turns,
        "wall_s": time.perf_counter() - wall, "outlier_matches": slam.outlier_pairs / slam.num_particles,
        "occupancy": {"probability": grid.probability(), "known": grid.observed.copy(), "origin": grid.origin,
                      "resolution": grid.res, "free_thresh": cfg.grid.free_below,
                      "occupied_thresh": cfg.grid.occupied_above} if grid.observed.size else None,  # None: no scan came
    }


def _odom_in_map(start: np.ndarray, odom0: np.ndarray, odom: np.ndarray) -> np.ndarray:
    """Dead reckoning in the map frame: the start pose composed with the odometry since the start."""
    from mrslam_core.geometry.se2 import compose

    return compose(start, between(odom0, odom))


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="mrslam team", description=__doc__)
    ap.add_argument("--config", help="YAML with TeamConfig keys")
    ap.add_argument("--robots", type=int)
    ap.add_argument("--seconds", type=float)
    ap.add_argument("--out", default="runs/team")
    args = ap.parse_args(argv)
    try:
        cfg = load_yaml(TeamConfig, args.config) if args.config else TeamConfig()
    except ConfigError as exc:
        print(f"mrslam team: {exc}", file=sys.stderr)
        return 2
    if args.robots:
        cfg = replace(cfg, robots=args.robots)
    if args.seconds:
        cfg = replace(cfg, seconds=args.seconds)
    print(f"simulated team: {cfg.robots} robots, {cfg.seconds:.0f} s in world {cfg.sim.world}", flush=True)
    res = run(cfg, progress=True)
    report = write_run(args.out, res["trajectories"], cfg, res["update_ms"], res["landmarks"],
                       extra={"explored_fraction": res["explored_fraction"], "dropped": res["dropped"],
                              "frontend_drops": res["frontend_drops"], "wall_s": res["wall_s"],
                              "exploration_state": res["exploration_state"], "stalls": res["stalls"], "held": res["held"],
                              "boxed_in": res["boxed_in"], "long_turns": res["long_turns"],
                              "turn_backoffs": res["turn_backoffs"], "blocked_turns": res["blocked_turns"],
                              "outlier_matches": res["outlier_matches"], "map_checks": res["map_checks"],
                              "relocalizations": res["relocalizations"]}, occupancy=res["occupancy"])
    for name, r in report["robots"].items():
        print(f"  {name}: ATE {r['ate_rmse_m']:.3f} m (odometry {r['odom_ate_rmse_m']:.3f} m), RPE {r['rpe_rmse_m']:.3f} m")
    u = report["update_ms"]
    print(f"  landmarks {report['landmarks']}; explored {report['explored_fraction']}; filter step p50 {u['p50']:.1f} "
          f"p95 {u['p95']:.1f} max {u['max']:.1f} ms; wall {res['wall_s']:.0f} s")
    print(f"wrote {Path(args.out) / 'report.json'}")
    return 0
