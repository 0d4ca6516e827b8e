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
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal

import numpy as np

from mrslam_core.configio import ConfigError, load_yaml, positive_int, profile_section
from mrslam_core.control.config import ControlConfig
from mrslam_core.control.controller import Controller
from mrslam_core.evaluation.report import write_run
from mrslam_core.exploration.config import ExplorationConfig, GridConfig
from mrslam_core.exploration.coverage import explored_fraction
from mrslam_core.exploration.explorer import Explorer, State
from mrslam_core.exploration.grid import OccupancyGrid, Scan
from mrslam_core.exploration.own_frame import OwnFrameExploration
from mrslam_core.frontend.camera import StereoRig
from mrslam_core.frontend.config import FiducialConfig, FrontendConfig
from mrslam_core.frontend.frontend import Frontend, VisualOdometry
from mrslam_core.frontend.odometry import planar_motion
from mrslam_core.fusion.config import FusionConfig
from mrslam_core.geometry.se2 import between, planar_from_matrix
from mrslam_core.pipelines.central import CentralConfig, CentralMapper, MapCheckConfig
from mrslam_core.pipelines.odometry import SOURCES, OdometrySource, visual_step_covariance
from mrslam_core.sim.config import SimConfig
from mrslam_core.sim.simulation import Simulation
from mrslam_core.slam.config import FilterConfig


#: the simulated team profile (in configio.PROFILES): TeamConfig's frontend, filter, exploration and control defaults
TEAM_PROFILE = "sim_team.yaml"


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
        odometry: what the central mapper takes as each robot's odometry: ``wheel`` (the
            simulator's), ``visual`` (the frontend's visual odometry) or ``fused`` (both, step by
            step with their information matrices, :class:`OdometryFusion`, the wheels' noise
            model being ``filter.motion``). The frontends' search windows follow the wheels in all.
        unknown_start: robots whose start pose the central mapper is not given (names
            ``robot1`` … ``robotK``): each maps and explores alone in its own start frame until
            the mapper joins it (map alignment, or ``rendezvous``), then hands its grid over and
            explores with the team (:class:`~mrslam_core.exploration.own_frame.OwnFrameExploration`).
            If every robot is listed, robot1's start pose defines the map frame.
        rendezvous: joins go through the team's evidence gate: a strong alignment joins alone, a
            weak one (its error at the robot beyond the spread the joined cloud carries) waits
            for a strong one or an agreeing mutual tag sighting (tags: ``fiducials``). Off,
            every consistent alignment joins (docs/fusion.md).
        fusion: map alignment and joining (:class:`~mrslam_core.fusion.config.FusionConfig`).
        frontend, fiducials, filter, exploration, control, grid: by default the simulated team
            profile (config/sim_team.yaml). ``fiducials``: the robots whose tags the simulator
            draws and the frontends report as sightings.
    """

    robots: int = 3
    seconds: float = 120.0
    control_period: float = 0.2
    explore: bool = True
    odometry: Literal["wheel", "visual", "fused"] = "wheel"
    unknown_start: tuple[str, ...] = ()
    rendezvous: bool = True
    fusion: FusionConfig = field(default_factory=FusionConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    frontend: FrontendConfig = field(default_factory=lambda: profile_section(FrontendConfig, TEAM_PROFILE, "frontend"))
    fiducials: FiducialConfig = field(default_factory=lambda: profile_section(FiducialConfig, TEAM_PROFILE, "fiducials"))
    filter: FilterConfig = field(default_factory=lambda: profile_section(FilterConfig, TEAM_PROFILE, "filter"))
    map_check: MapCheckConfig = field(default_factory=MapCheckConfig)
    exploration: ExplorationConfig = field(default_factory=lambda: profile_section(ExplorationConfig, TEAM_PROFILE, "exploration"))
    control: ControlConfig = field(default_factory=lambda: profile_section(ControlConfig, TEAM_PROFILE, "control"))
    grid: GridConfig = field(default_factory=lambda: profile_section(GridConfig, TEAM_PROFILE, "grid"))

    def __post_init__(self) -> None:
        if self.robots < 1 or not self.seconds > 0 or not self.control_period > 0:
            raise ValueError("need robots >= 1, seconds > 0 and control_period > 0")
        if self.odometry not in SOURCES:
            raise ValueError(f"odometry must be one of {SOURCES}, not {self.odometry!r}")
        stray = sorted(set(self.unknown_start) - {f"robot{i + 1}" for i in range(self.robots)})
        if stray:
            raise ValueError(f"unknown_start names robots the team of {self.robots} does not have: {stray}")


def run(cfg: TeamConfig, progress: bool = False, coverage_every: float = 0.0,
        on_frame: Callable[[str, Frontend, np.ndarray, bool], None] | None = None) -> dict:
    """Run the closed loop; returns trajectories, step times, the map and counters (among them
    ``sightings``: per robot, the other robots' tags its frontend reported).

    ``coverage_every`` > 0: every that many simulated seconds [s], and at the end, the explored
    fraction of the world's reachable free area is recorded as "coverage" (C, 2): time [s],
    fraction (else "coverage" is None).

    ``on_frame(robot, frontend, truth, dropped)``: called after each frontend step with the
    robot's true pose (3,) (x [m], y [m], θ [rad]) at the frame; ``dropped``: the frontend
    published nothing for it (tools that compare frames with the truth).
    """
    sim = Simulation(cfg.sim, fiducials=cfg.fiducials)
    names = [f"robot{i + 1}" for i in range(cfg.robots)]
    for n in names:
        sim.add_robot(n)
    starts = np.array([sim.ground_truth(n) for n in names])
    rig = StereoRig(*sim.camera_infos(), sim.camera_extrinsic())
    frontends = {n: Frontend(rig, cfg.frontend, robot=n, fiducials=cfg.fiducials) for n in names}
    mapper = CentralMapper(CentralConfig(
        robots=tuple(names), start_poses=tuple(float(v) for v in starts.ravel()), unknown_start=cfg.unknown_start,
        rendezvous=cfg.rendezvous, map_check=cfg.map_check, filter=cfg.filter, fusion=cfg.fusion))
    slam = mapper.slam
    grid = OccupancyGrid(cfg.grid)
    controller = Controller(cfg.control)
    explorer = Explorer(cfg.exploration, [n for n in names if n not in mapper.local], controller)
    own: dict[str, OwnFrameExploration] = {}  # the robots not in the map frame (yet)
    odom0 = {n: sim.odometry(n)[0] for n in names}
    at_frame = dict(odom0)  # each robot's odometry at its previous frame: the frontend's motion prior
    feed = _OdometryFeed(cfg, mapper, names)
    for n in names:
        feed.wheel(n, sim.time_ns, odom0[n])
    sightings = dict.fromkeys(names, 0)  # the other robots' tags each one reported
    # a robot's trajectory starts at its known start pose, or at its join
    rec = {n: {"t": [0.0], "est": [starts[i]], "gt": [starts[i]], "odom": [starts[i]]} if n in slam.index
           else {"t": [], "est": [], "gt": [], "odom": []} for i, n in enumerate(names)}
    next_control = 0
    control_ns = int(cfg.control_period * 1e9)
    truth_free = sim.world.reachable_free(cfg.grid.resolution)
    coverage: list[tuple[float, float]] | None = [] if coverage_every > 0 else None
    next_coverage, coverage_ns = 0, int(coverage_every * 1e9)
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
            if on_frame is not None:
                on_frame(n, frontends[n], sim.ground_truth(n), obs is None)
            feed.wheel(n, frame.stamp_ns, odom)
            feed.visual(n, frontends[n].odometry)
            if obs is None:  # a dropped frame: the next set carries its motion
                continue
            sightings[n] += len(obs.sightings)
            mapper.add_observations(obs)
            scans[n] = scan
        for n in mapper.local:  # an unknown start, or an odometry reset: on its own until it joins
            if n not in own:
                own[n] = OwnFrameExploration.create(n, cfg.exploration, cfg.grid, controller)
                if n in explorer.robots:
                    explorer.robots.remove(n)
                    explorer.goals.pop(n, None)
        for done in mapper.process(flush=True):
            n = done.robot
            if not done.merged:  # its own frame, or awaiting its re-localisation: no map pose
                if n in own and scans.get(n) is not None:
                    own[n].insert(done.pose, Scan.from_obstacle_scan(scans[n]), _teammates(rec, n))
                continue
            r = rec[n]
            r["t"].append(done.stamp_ns * 1e-9)
            r["est"].append(done.pose)
            r["gt"].append(sim.ground_truth(n))
            r["odom"].append(_odom_in_map(starts[names.index(n)], feed.first[n], done.odom))
            if scans.get(n) is not None:
                grid.insert(done.pose, Scan.from_obstacle_scan(scans[n]), _teammates(rec, n))
        # joined: its grid goes into the team's, and it explores with the team
        for n in [n for n in own if n not in mapper.local]:
            join = [m for m in mapper.merges if m["robot"] == n and m["accepted"]][-1]
            own.pop(n).hand_over(grid, np.array(join["transform"]))
            explorer.robots.append(n)
        if coverage is not None and sim.time_ns >= next_coverage:
            next_coverage += coverage_ns
            coverage.append((sim.time_ns * 1e-9, _explored(grid, truth_free, cfg.grid.resolution)))
        if cfg.explore and sim.time_ns >= next_control:
            next_control += control_ns
            now = sim.time_ns * 1e-9
            est = slam.estimate()
            poses = {n: est.mean[slam.index[n]] for n in explorer.robots}
            own_poses = {n: mapper.local[n].estimate().mean[0] for n in own}
            for n in names:  # the bumpers: what the robots touch is an obstacle
                touch = sim.contacts(n)
                if len(touch) and n in own:
                    own[n].explorer.bumped(own[n].grid, n, touch, own_poses, now)
                elif len(touch):
                    explorer.bumped(grid, n, touch, poses, now)
            commands = explorer.step(grid, poses, now)
            for n, o in own.items():
                commands |= o.explorer.step(o.grid, {n: own_poses[n]}, now)
            for n, (v, w) in commands.items():
                sim.set_command(n, v, w)
            if explorer.state is State.COMPLETE:
                break
        if progress and sim.time_ns % int(10e9) == 0:
            print(f"  t = {sim.time_ns * 1e-9:5.0f} s  wall {time.perf_counter() - wall:6.1f} s", file=sys.stderr, flush=True)
    trajectories = {n: {k: np.array(v) for k, v in r.items()} for n, r in rec.items() if r["t"]}
    _, mean, cov, _, _ = slam.best_map()
    end_s = sim.time_ns * 1e-9
    sim.close()
    explored = _explored(grid, truth_free, cfg.grid.resolution)
    if coverage is not None and coverage[-1][0] < end_s:
        coverage.append((end_s, explored))
    return {
        "trajectories": trajectories, "update_ms": np.array(mapper.update_ms), "landmarks": {"mean": mean, "cov": cov},
        "dropped": dict(slam.dropped) | dict(mapper.drops), "map_checks": dict(mapper.map_checks),
        "relocalizations": mapper.relocalizations, "sightings": sightings, "merges": list(mapper.merges),
        "unmerged": sorted(own),
        "frontend_drops": {n: dict(f.drops) | (dict(f.fiducials.drops) if f.fiducials else {}) for n, f in frontends.items()},
        "explored_fraction": explored, "coverage": None if coverage is None else np.array(coverage),
        "exploration_state": explorer.state.value, **explorer.controller.counters(),
        "bumped_cells": explorer.bumped_cells, "bumped_goals": explorer.bumped_goals,
        "wall_s": time.perf_counter() - wall, "outlier_matches": slam.outlier_pairs / slam.num_particles,
        "occupancy": {"probability": grid.probability(), "known": grid.observed.copy(), "origin": grid.origin,
                      "resolution": grid.res, "free_thresh": cfg.grid.free_below,
                      "occupied_thresh": cfg.grid.occupied_above} if grid.observed.size else None,  # None: no scan came
    }


class _OdometryFeed:
    """Each robot's odometry into the central mapper from the configured source (``cfg.odometry``).

    ``first[robot]``: the robot's first odometry pose given to the mapper (3,), the start of its
    dead reckoning.
    """

    def __init__(self, cfg: TeamConfig, mapper: CentralMapper, names: list[str]):
        self.mapper = mapper
        self.sources = {n: OdometrySource(cfg.odometry, cfg.filter.motion) for n in names}
        self.first: dict[str, np.ndarray] = {}
        self._vo_stamp: dict[str, int] = {}

    def wheel(self, robot: str, stamp_ns: int, pose: np.ndarray) -> None:
        self._give(robot, self.sources[robot].wheel(stamp_ns, pose))

    def visual(self, robot: str, vo: VisualOdometry | None) -> None:
        """The frontend's visual odometry after a frame (:class:`VisualOdometry`, None before one)."""
        source = self.sources[robot]
        if not source.uses_visual or vo is None or self._vo_stamp.get(robot) == vo.stamp_ns:
            return
        prev = self._vo_stamp.get(robot)
        self._vo_stamp[robot] = vo.stamp_ns
        dt = 1.0 if prev is None else (vo.stamp_ns - prev) * 1e-9  # a first frame's step is not used
        twist_cov = visual_step_covariance(vo.cov) / dt**2
        self._give(robot, source.visual(vo.stamp_ns, planar_from_matrix(vo.pose), twist_cov))

    def _give(self, robot: str, poses: list[tuple[int, np.ndarray]]) -> None:
        for stamp, pose in poses:
            self.first.setdefault(robot, np.asarray(pose, float))
            self.mapper.add_odometry(robot, stamp, pose)


def write_team_run(out: str | Path, cfg: TeamConfig, res: dict) -> dict:
    """The run folder of a :func:`run` result (``evaluation.report.write_run``); returns the report."""
    counters = ("explored_fraction", "dropped", "frontend_drops", "wall_s", "exploration_state", "boxed_in",
                "long_turns", "turn_backoffs", "blocked_turns", "outlier_matches", "map_checks",
                "relocalizations", "sightings", "merges", "unmerged")
    return write_run(out, res["trajectories"], cfg, res["update_ms"], res["landmarks"],
                     extra={k: res[k] for k in counters}, occupancy=res["occupancy"])


def _explored(grid: OccupancyGrid, truth_free: np.ndarray, resolution: float) -> float:
    return explored_fraction(grid.observed, grid.origin, grid.res, truth_free, resolution)


def _teammates(rec: dict[str, dict], robot: str) -> np.ndarray:
    """(T, 2) [m] the newest map-frame positions of the robots other than ``robot`` that have one."""
    return np.array([r["est"][-1][:2] for o, r in rec.items() if o != robot and r["est"]]).reshape(-1, 2)


def _odom_in_map(start: np.ndarray, odom0: np.ndarray, odom: np.ndarray) -> np.ndarray:
    """Dead reckoning in the map frame: the start pose composed with the odometry since the start."""
    from mrslam_core.geometry.se2 import compose

    return compose(start, between(odom0, odom))


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="mrslam team", description=__doc__)
    ap.add_argument("--config", help="YAML with TeamConfig keys")
    ap.add_argument("--robots", type=positive_int, help="team size")
    ap.add_argument("--seconds", type=float)
    ap.add_argument("--unknown-start", nargs="+", metavar="ROBOT",
                    help="robots whose start pose the mapper is not given (they join by map alignment)")
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
    try:
        if args.unknown_start:
            cfg = replace(cfg, unknown_start=tuple(args.unknown_start))
    except ValueError as exc:
        print(f"mrslam team: {exc}", file=sys.stderr)
        return 2
    print(f"simulated team: {cfg.robots} robots, {cfg.seconds:.0f} s in world {cfg.sim.world}", flush=True)
    res = run(cfg, progress=True)
    report = write_team_run(args.out, cfg, res)
    for m in res["merges"]:
        if m["accepted"]:
            print(f"  {m['robot']} joined at {m['stamp_ns'] * 1e-9:.1f} s by {m['via']}")
    for name in res["unmerged"]:
        print(f"  {name} did not join (no map pose, not in the report's robots)")
    for name, r in report["robots"].items():
        print(f"  {name}: ATE {r['ate_rmse_m']:.3f} m (odometry {r['odom_ate_rmse_m']:.3f} m), RPE {r['rpe_rmse_m']:.3f} m")
    u = report["update_ms"]
    print(f"  landmarks {report['landmarks']}; explored {report['explored_fraction']}; filter step p50 {u['p50']:.1f} "
          f"p95 {u['p95']:.1f} max {u['max']:.1f} ms; wall {res['wall_s']:.0f} s")
    print(f"wrote {Path(args.out) / 'report.json'}")
    return 0
