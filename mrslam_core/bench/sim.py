"""``mrslam bench sim``: stereo pairs rendered per wall-clock second, and a team run's duration.

Robots drive slow circles in the default office; every robot renders its stereo pair at the
camera rate. Figures: pairs per second at 320×240 and 640×480 for 1 and 3 robots, and the wall
time of a 3-robot run of ``--seconds`` simulated seconds at the default resolution and rate.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

from mrslam_core.sim.config import SimConfig
from mrslam_core.sim.simulation import Simulation


def pairs_per_second(width: int, height: int, robots: int, pairs: int = 6) -> float:
    """Stereo pairs rendered per wall-clock second (physics between frames included)."""
    cfg = replace(SimConfig(), camera=replace(SimConfig().camera, width=width, height=height))
    with Simulation(cfg) as sim:
        names = [f"robot{i + 1}" for i in range(robots)]
        for n in names:
            sim.add_robot(n)
            sim.set_command(n, 0.2, 0.2)
        sim.render_stereo(names[0])  # warm-up: textures and shaders loaded
        done = 0
        t0 = time.perf_counter()
        while done < pairs * robots:
            for n in sim.step_until_frame():
                sim.render_stereo(n)
                done += 1
        return done / (time.perf_counter() - t0)


def team_run(seconds: float, robots: int = 3) -> float:
    """Wall time [s] of a team run with default rendering for ``seconds`` simulated seconds
    (world construction with its textures included)."""
    t0 = time.perf_counter()
    with Simulation(SimConfig()) as sim:
        names = [f"robot{i + 1}" for i in range(robots)]
        for n in names:
            sim.add_robot(n)
            sim.set_command(n, 0.3, 0.15)
        while sim.time_ns < seconds * 1e9:
            for n in sim.step_until_frame():
                sim.render_stereo(n)
    return time.perf_counter() - t0


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="mrslam bench sim", description=__doc__)
    ap.add_argument("--seconds", type=float, default=120.0, help="simulated seconds of the team run")
    ap.add_argument("--out", default="runs/bench")
    args = ap.parse_args(argv)
    rows = []
    for w, h in ((320, 240), (640, 480)):
        for k in (1, 3):
            rate = pairs_per_second(w, h, k)
            rows.append({"width": w, "height": h, "robots": k, "pairs_per_s": rate})
            print(f"{w}x{h} robots={k}: {rate:5.2f} stereo pairs/s", flush=True)
    cam = SimConfig().camera
    wall = team_run(args.seconds)
    print(f"3 robots, {args.seconds:.0f} simulated s at {cam.width}x{cam.height}, {cam.rate_hz} Hz: {wall:.1f} s wall")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "sim.json").write_text(json.dumps({"rendering": rows, "team_run_wall_s": wall,
                                              "team_run_sim_s": args.seconds}, indent=2))
    print(f"wrote {out / 'sim.json'}")
    return 0
