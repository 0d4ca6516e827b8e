"""``mrslam experiment blind_frames RUN ROBOT START END``: where a simulated robot's points went.

Re-renders robot ROBOT's stereo pairs of a simulated run folder (``mrslam team`` or ``mrslam demo``:
its config.yaml and trajectories/robotN_gt.tum, poses interpolated) at the camera rate from START to END [s], every robot
of the run placed at its ground-truth pose, and runs a fresh frontend on them (the run's frontend
config, changed by ``--set key=value``). Per frame it counts what each stage kept: Harris (or the
configured detector's) keypoints, stereo matches within the depth limits, points tracked over 2 and
over ``min_track_length`` frames, and the observations published. The tracks start at START, so
the first ``min_track_length - 1`` frames publish nothing. A blind spell (few points published)
is a detector, a stereo matching or a tracking loss, and this tells which.
"""

from __future__ import annotations

import argparse
from dataclasses import fields, replace
from pathlib import Path

import numpy as np
import yaml

from mrslam_core.configio import from_dict
from mrslam_core.evaluation.metrics import interpolate_poses
from mrslam_core.evaluation.tum import read_tum
from mrslam_core.experiments._output import write_tables
from mrslam_core.frontend import Frontend, FrontendConfig, StereoRig
from mrslam_core.pipelines.team import TeamConfig
from mrslam_core.sim.simulation import Simulation


def load_team(run: Path) -> TeamConfig:
    """The team config of a run folder: ``team:`` of a demo's config.yaml, or a team run's whole file."""
    data = yaml.safe_load((run / "config.yaml").read_text()) or {}
    return from_dict(TeamConfig, data.get("team", data))


def overrides(cfg: FrontendConfig, pairs: list[str]) -> FrontendConfig:
    """``cfg`` with ``key=value`` strings applied (values as the field's type: 1e-5, true, 64)."""
    names = {f.name for f in fields(FrontendConfig)}
    change = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or key not in names:
            raise SystemExit(f"--set wants key=value with a FrontendConfig key, got {pair!r}")
        change[key] = type(getattr(cfg, key))(yaml.safe_load(value))
    return replace(cfg, **change)


def stage_counts(run: Path, robot: str, start: float, end: float, frontend: FrontendConfig) -> list[dict]:
    """One dict per re-rendered frame of ``robot`` in [start, end] s: time, true pose and counts."""
    team = load_team(run)
    truth = {}
    for path in sorted((run / "trajectories").glob("*_gt.tum")):
        truth[path.name[: -len("_gt.tum")]] = read_tum(path)
    if robot not in truth:
        raise SystemExit(f"{run}/trajectories has no {robot}_gt.tum (have {sorted(truth)})")
    rows = []
    with Simulation(team.sim) as sim:
        for name in truth:
            sim.add_robot(name)
        rig = StereoRig(*sim.camera_infos(), sim.camera_extrinsic())
        fe = Frontend(rig, frontend, robot=robot)
        period = 1.0 / team.sim.camera.rate_hz
        for stamp in np.arange(start, end + 1e-9, period):
            for name, (t, poses) in truth.items():
                sim.place(name, interpolate_poses(np.array([stamp]), t, poses)[0])
            frame = sim.render_stereo(robot)
            obs, _ = fe.step(frame.left, frame.right, int(round(stamp * 1e9)), encoding=frame.encoding)
            if obs is None:
                rows.append({"t": float(stamp), "dropped": dict(fe.drops)})
                continue
            last = fe.last_frame
            rows.append({
                "t": float(stamp), "pose": [float(v) for v in sim.ground_truth(robot)], "keypoints": last.detected,
                "stereo": last.matched, "in_depth": len(last.xy),
                "tracked_2": int((last.track_length >= 2).sum()),
                "tracked_min": int((last.track_length >= frontend.min_track_length).sum()),
                "published": len(obs),
            })
    return rows


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="mrslam experiment blind_frames", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run", type=Path, help="run folder of mrslam team or mrslam demo")
    ap.add_argument("robot")
    ap.add_argument("start", type=float, help="first frame [s, run time]")
    ap.add_argument("end", type=float, help="last frame [s]")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="frontend config change")
    ap.add_argument("--out", default="runs/experiments")
    args = ap.parse_args(argv)
    frontend = overrides(load_team(args.run).frontend, args.set)
    rows = stage_counts(args.run, args.robot, args.start, args.end, frontend)
    lines = [f"{args.robot} of {args.run}, re-rendered from ground truth {args.start:g}-{args.end:g} s"
             + (f", {', '.join(args.set)}" if args.set else ""), "",
             "| t [s] | x [m] | y [m] | θ [deg] | keypoints | stereo | in depth | tracked 2 | "
             f"tracked {frontend.min_track_length} | published |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "dropped" in r:
            lines.append(f"| {r['t']:.1f} | dropped {r['dropped']} | | | | | | | | |")
            continue
        x, y, th = r["pose"]
        lines.append(f"| {r['t']:.1f} | {x:.2f} | {y:.2f} | {np.degrees(th):.1f} | {r['keypoints']} | {r['stereo']} | "
                     f"{r['in_depth']} | {r['tracked_2']} | {r['tracked_min']} | {r['published']} |")
    write_tables(args.out, f"blind_frames_{args.robot}", "\n".join(lines), rows)
    return 0
