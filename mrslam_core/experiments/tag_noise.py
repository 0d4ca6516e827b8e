"""``mrslam experiment tag_noise [--worlds W ...] [--placements N]``: the robot-tag sightings
against the simulator's truth, and whether their covariance is calibrated.

In each world robot1 stands at a start pose with a random heading and robot2 at a random pose
0.7-4 m ahead of it (within ±0.5 rad of its camera axis, any heading, with a clear line of sight
at tag height); robot1's rendered pair goes through the frontend's tag detector
(:class:`~mrslam_core.frontend.fiducials.FiducialDetector`, the team profile's ``fiducials`` with
robots 1 and 2). Per distance band: the share of placements that gave a sighting, the range and
bearing errors against the truth (mean and standard deviation) beside the σ the detector
states, and the normalised error eᵀΣ⁻¹e (NIS: χ²(2), mean 2 when Σ is right; the share above
13.8, χ²(2) at 0.999). Also the mean NIS of range and bearing alone (1 each when right).
"""

from __future__ import annotations

import argparse
from collections import Counter
from dataclasses import replace

import numpy as np
import pybullet as p

from mrslam_core.experiments._output import write_tables
from mrslam_core.frontend import StereoRig
from mrslam_core.frontend.config import FiducialConfig
from mrslam_core.frontend.fiducials import FiducialDetector
from mrslam_core.geometry.se2 import between, wrap_angle
from mrslam_core.pipelines.team import TeamConfig
from mrslam_core.sim.simulation import Simulation

#: the worlds measured by default: the office, a generated ring and a generated warehouse
WORLDS = ("office", "gen:ring:1:apart", "gen:warehouse:3:apart")
#: distance bands of the table [m]
BANDS = (0.7, 1.5, 2.5, 3.2, 4.0)
#: χ²(2) at 0.999
NIS_GATE = 13.8


def measure(world: str, placements: int, fiducials: FiducialConfig, seed: int = 0) -> tuple[np.ndarray, Counter]:
    """Rows (K, 9) of every placement: distance [m], sighted (0/1), range and bearing error
    [m, rad], stated σ of range and bearing, NIS, and the NIS of range and bearing alone (NaN
    where nothing was sighted); and the detector's drops."""
    cfg = replace(fiducials, robots=("robot1", "robot2"))
    team = TeamConfig()
    rng = np.random.default_rng(seed)
    rows = []
    with Simulation(replace(team.sim, world=world, seed=seed), fiducials=cfg) as sim:
        sim.add_robot("robot1")
        sim.add_robot("robot2")
        rig = StereoRig(*sim.camera_infos(), sim.camera_extrinsic())
        det = FiducialDetector(rig, cfg, "robot1")
        starts = np.asarray(sim.world.start_poses, float)
        while len(rows) < placements:
            r1 = starts[len(rows) % len(starts)] + np.array([0.0, 0.0, rng.uniform(-np.pi, np.pi)])
            dist, off, yaw = rng.uniform(BANDS[0], BANDS[-1]), rng.uniform(-0.5, 0.5), rng.uniform(-np.pi, np.pi)
            r2 = np.array([r1[0] + dist * np.cos(r1[2] + off), r1[1] + dist * np.sin(r1[2] + off), yaw])
            h = cfg.carrier_height
            if p.rayTest([r1[0], r1[1], h], [r2[0], r2[1], h], physicsClientId=sim.client)[0][0] >= 0:
                continue  # a wall between them
            sim.place("robot1", r1)
            sim.place("robot2", r2)
            frame = sim.render_stereo("robot1")
            found = det.detect(frame.left, frame.right).sightings
            rel = between(r1, r2)
            truth = np.array([np.hypot(rel[0], rel[1]), np.arctan2(rel[1], rel[0])])
            if not found:
                rows.append([dist, 0.0] + [np.nan] * 7)
                continue
            s = found[0]
            e = s.z - truth
            e[1] = wrap_angle(e[1])
            rows.append([dist, 1.0, e[0], e[1], np.sqrt(s.cov[0, 0]), np.sqrt(s.cov[1, 1]),
                         float(e @ np.linalg.solve(s.cov, e)), e[0] ** 2 / s.cov[0, 0], e[1] ** 2 / s.cov[1, 1]])
        return np.array(rows), det.drops


def table(rows: np.ndarray) -> list[dict]:
    """Per distance band (and all): the figures of the module docstring."""
    out = []
    for lo, hi in [*zip(BANDS[:-1], BANDS[1:]), (BANDS[0], BANDS[-1])]:
        band = rows[(rows[:, 0] >= lo) & (rows[:, 0] < hi)]
        seen = band[band[:, 1] > 0]
        if not len(band):
            continue
        def stat(f, col: int) -> float:
            return float(f(seen[:, col])) if len(seen) else np.nan

        out.append({
            "from_m": lo, "to_m": hi, "placed": len(band), "sighted": len(seen),
            "range_mean_m": stat(np.mean, 2), "range_std_m": stat(np.std, 2), "range_sigma_m": stat(np.mean, 4),
            "bearing_std_deg": float(np.degrees(stat(np.std, 3))),
            "bearing_sigma_deg": float(np.degrees(stat(np.mean, 5))),
            "nis_mean": stat(np.mean, 6), "nis_over_gate": int(np.sum(seen[:, 6] > NIS_GATE)),
            "nis_range": stat(np.mean, 7), "nis_bearing": stat(np.mean, 8),
        })
    return out


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="mrslam experiment tag_noise", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--worlds", nargs="+", default=list(WORLDS))
    ap.add_argument("--placements", type=int, default=300, help="placements per world")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default="runs/experiments")
    args = ap.parse_args(argv)
    fiducials = TeamConfig().fiducials
    lines = [f"Robot tags against the truth: {args.placements} placements per world, seed {args.seed}; "
             f"{fiducials.dictionary}, {fiducials.tag_size:g} m tags, sigma_px {fiducials.sigma_px:g}, "
             f"normal_sigma_px {fiducials.normal_sigma_px:g}", "",
             "| world | distance [m] | sighted | range error mean / std [m] | stated σ [m] | bearing error std [°] | "
             "stated σ [°] | NIS mean (range, bearing) | NIS > 13.8 |", "|---|---|---|---|---|---|---|---|---|"]
    data = {}
    for world in args.worlds:
        rows, drops = measure(world, args.placements, fiducials, args.seed)
        bands = table(rows)
        data[world] = {"bands": bands, "drops": dict(drops)}
        for b in bands:
            what = "all" if (b["from_m"], b["to_m"]) == (BANDS[0], BANDS[-1]) else f"{b['from_m']:g}-{b['to_m']:g}"
            lines.append(f"| {world} | {what} | {b['sighted']}/{b['placed']} | {b['range_mean_m']:+.3f} / "
                         f"{b['range_std_m']:.3f} | {b['range_sigma_m']:.3f} | {b['bearing_std_deg']:.2f} | "
                         f"{b['bearing_sigma_deg']:.2f} | {b['nis_mean']:.2f} ({b['nis_range']:.2f}, "
                         f"{b['nis_bearing']:.2f}) | {b['nis_over_gate']} |")
        lines.append(f"| {world} | drops | {dict(drops)} | | | | | | |")
    write_tables(args.out, "tag_noise", "\n".join(lines), data)
    return 0
