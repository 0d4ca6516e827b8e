"""``mrslam experiment sweep``: the simulated team, closed loop in one process, over many worlds.

For every world × seed: ``mrslam team``'s closed loop (``pipelines.team.run``, the team defaults,
``--robots`` robots, the world's first start poses; the seed is the simulator's and the filter's)
and, as its reference, exploration alone with perfect poses in the 2-D simulator
(``pipelines.sim2d``, as ``mrslam experiment exploration``) with the same robots, start poses,
seed, exploration, control and grid settings, and a range sensor of the stereo head's field of view,
the frontend's scan range and the camera rate. Both measure the explored fraction of the world's
reachable free area the same way (``World.reachable_free`` at the grid resolution).

Worlds: ``--worlds`` takes world names (built-in, YAML paths, ``gen:KIND:SEED[:STARTS[:ROBOTS]]``), and
``--suite N`` adds N generated worlds: the kinds office, ring, open, warehouse in turn with seeds
0..N-1, start modes alternating so that each kind comes with both (``worldgen.suite``).

Per run: each robot's ATE, its odometry's ATE and their ratio (``evaluation.report.robot_metrics``),
the explored fraction every second, the time to 90 % explored against the reference's, how long
robots stood, and the central filter's step time. Standing is measured two ways, both reported:

- still (``still_s``, the criterion): the longest time no point of the robot's body (its
  footprint, ``ControlConfig.platform``) moved more than 0.2 m from where it was at the start of
  that time. A robot turning on the spot towards its path is not still (the simulated Pioneer's
  corners, 0.33 m from its axle, sweep 0.2 m in 36° of turn: 1.8 s at the team's 0.35 rad/s);
  one pushing against an obstacle or a teammate, recovering back and forth within 0.2 m, or
  standing with no goal is.
- stay (``stuck_s``, the former measure, kept for comparison with earlier sweeps): the longest
  time the robot's position stayed within 0.2 m, turning on the spot included.

A run lasts ``--seconds`` of simulated time, by default ``RUN_FACTOR`` × the reference's time to 90 %
(``REFERENCE_SECONDS`` where the reference never gets there), or until exploration is complete.

Writes under ``--out``: ``runs/<world>__seed<S>__robots<K>.json`` as each run ends, beside the
run's folder as ``mrslam team --out`` writes it (report, trajectories, occupancy map, plots); a run
whose JSON is there with the same request is not run again, so a sweep can be resumed. Then
``sweep.md``/``sweep.json`` (the criteria and a row per run) and the plots ``sweep_ate.png``,
``sweep_ratio.png``, ``sweep_explored.png``, ``sweep_stuck.png``, ``sweep_latency.png``.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import re
import sys
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from mrslam_core.configio import non_negative_int, positive_float, positive_int
from mrslam_core.control.platform import PlatformConfig
from mrslam_core.errors import InputError
from mrslam_core.evaluation.metrics import longest_stay
from mrslam_core.evaluation.report import latency_summary
from mrslam_core.experiments._output import write_tables
from mrslam_core.experiments._sweep_plots import plot_all
from mrslam_core.experiments.exploration import time_to
from mrslam_core.exploration.coverage import explored_fraction
from mrslam_core.pipelines.sim2d import SensorConfig, TeamSim2D
from mrslam_core.pipelines.team import TeamConfig, write_team_run
from mrslam_core.pipelines.team import run as run_team
from mrslam_core.sim.world import World, load_world
from mrslam_core.sim.worldgen import suite

#: the criteria of a sweep: a robot-run meets the accuracy target with ATE <= ATE_MAX
#: and <= RATIO_MAX of its odometry's; MET_SHARE of the robot-runs must, and the median ATE be
#: <= MEDIAN_MAX; each run reaches EXPLORED within TIME_FACTOR × the reference's time; no robot is
#: still (no point of its body moved STUCK_RADIUS, :func:`longest_still`) longer than STUCK_MAX
ATE_MAX, RATIO_MAX, MET_SHARE, MEDIAN_MAX = 0.10, 0.30, 0.95, 0.04  # [m], [-], [-], [m]
EXPLORED, TIME_FACTOR = 0.9, 1.5
STUCK_RADIUS, STUCK_MAX = 0.2, 20.0  # [m], [s]
#: default run length, in times the reference's time to EXPLORED: a run that misses TIME_FACTOR
#: shows by how much
RUN_FACTOR = 2.0
#: the reference's time limit, and the run length where the reference never reaches EXPLORED [s]
REFERENCE_SECONDS = 1800.0
COVERAGE_EVERY = 1.0  # [s]
_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
#: the team run's event counters each run's JSON keeps (``pipelines.team.run``)
COUNTERS = ("boxed_in", "long_turns", "turn_backoffs", "blocked_turns", "bumped_cells", "bumped_goals")


def team_config(world: str, seed: int, robots: int) -> TeamConfig:
    """The team defaults with ``robots`` robots in ``world``, simulator and filter seeded with ``seed``."""
    base = TeamConfig(robots=robots)
    return replace(base, sim=replace(base.sim, world=world, seed=seed), filter=replace(base.filter, seed=seed))


class _Reference(TeamSim2D):
    """The 2-D simulation whose explored fraction is the closed loop's (``World.reachable_free``
    at the grid resolution, the grid compared cell centre by cell centre)."""

    def __init__(self, world: World, cfg: TeamConfig, seed: int):
        cam = cfg.sim.camera
        sensor = SensorConfig(fov=float(np.radians(cam.hfov_deg)), beams=cfg.frontend.scan_bins,
                              max_range=cfg.frontend.scan_max_range, rate_hz=cam.rate_hz)
        # the 2-D sensor's ranges are exact: its hits are not spread by a stereo range error
        super().__init__(world, cfg.robots, cfg.exploration, sensor=sensor, grid=replace(cfg.grid, range_noise=0.0),
                         seed=seed, control=cfg.control)
        self.truth_free = world.reachable_free(cfg.grid.resolution)
        self.truth_res = cfg.grid.resolution

    def explored_fraction(self) -> float:
        return explored_fraction(self.grid.observed, self.grid.origin, self.grid.res, self.truth_free, self.truth_res)


def reference(world: World, cfg: TeamConfig, seed: int) -> list[tuple[float, float]]:
    """Exploration alone with perfect poses: [(time [s], explored fraction)] once a second, until
    ``EXPLORED`` or ``REFERENCE_SECONDS``."""
    return _Reference(world, cfg, seed).run(REFERENCE_SECONDS, stop_at=EXPLORED)


def footprint_corners(platform: PlatformConfig) -> np.ndarray:
    """The corners (4, 2) [m] of ``platform``'s footprint in base_link (x forward, y left)."""
    half = platform.width / 2
    return np.array([[platform.front, half], [platform.front, -half], [-platform.rear, -half], [-platform.rear, half]])


def longest_still(t: np.ndarray, poses: np.ndarray, corners: np.ndarray, radius: float) -> tuple[float, int]:
    """Longest time a robot's body stayed put: the largest t_j − t_i [s] such that from i to j no
    corner of the footprint ``corners`` (C, 2) [m] (base_link) was ever more than ``radius`` [m]
    from where it was at i, and that i (times t (N,) [s], poses (N, 3) (x, y, θ) [m, rad] in one
    frame; the first such stretch where several are as long). The footprint is convex, so no
    point of the body moves farther than its farthest corner: a robot turning on the spot is
    still only until its corners have swept ``radius`` (36° for the simulated Pioneer's 0.33 m
    corner radius and 0.2 m); one driving or recovering back and forth within ``radius`` is
    still."""
    t = np.asarray(t, float)
    poses = np.asarray(poses, float)
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    # (N, C, 2): each corner in the map frame at each pose
    world = poses[:, None, :2] + np.stack([c[:, None] * corners[:, 0] - s[:, None] * corners[:, 1],
                                           s[:, None] * corners[:, 0] + c[:, None] * corners[:, 1]], -1)
    best, start = 0.0, 0
    for i in range(len(t)):
        moved = np.linalg.norm(world[i + 1:] - world[i], axis=2).max(axis=1, initial=0.0)
        away = np.flatnonzero(moved > radius)
        j = i + int(away[0]) if away.size else len(t) - 1  # the last index still within
        if t[j] - t[i] > best:
            best, start = float(t[j] - t[i]), i
    return best, start


def kind_of(world: str, loaded: World) -> str:
    """A generated world's kind, else the world's name."""
    return world.split(":")[1] if world.startswith("gen:") else loaded.name


def run_one(world: str, seed: int, robots: int, seconds: float | None, folder: Path) -> dict:
    """One closed-loop run and its reference; writes the run's folder (``mrslam team``'s: report,
    trajectories, occupancy map, plots) to ``folder`` and returns the per-run record (JSON-ready)."""
    loaded = load_world(world)
    cfg = team_config(world, seed, robots)
    ref_curve = reference(loaded, cfg, seed)
    ref_t90 = time_to(ref_curve, EXPLORED)
    limit = seconds or (RUN_FACTOR * ref_t90 if np.isfinite(ref_t90) else REFERENCE_SECONDS)
    cfg = replace(cfg, seconds=float(np.ceil(limit)))
    res = run_team(cfg, coverage_every=COVERAGE_EVERY)
    robots_out = write_team_run(folder, cfg, res)["robots"]
    corners = footprint_corners(cfg.control.platform)
    for name, tr in res["trajectories"].items():
        stuck, i = longest_stay(tr["t"], tr["gt"], STUCK_RADIUS)
        still, k = longest_still(tr["t"], tr["gt"], corners, STUCK_RADIUS)
        robots_out[name] |= {"stuck_s": stuck, "stuck_from_s": float(tr["t"][i]),
                             "stuck_at": [float(v) for v in tr["gt"][i, :2]],
                             "still_s": still, "still_from_s": float(tr["t"][k]),
                             "still_at": [float(v) for v in tr["gt"][k, :2]]}
    coverage = res["coverage"]
    t90 = time_to(coverage, EXPLORED)
    ms = res["update_ms"]
    return {
        "request": {"world": world, "seed": seed, "robots": robots, "seconds": seconds}, "folder": folder.name,
        "world": world, "kind": kind_of(world, loaded), "size": list(loaded.size), "seed": seed,
        "seconds": float(coverage[-1, 0]), "wall_s": res["wall_s"], "robots": robots_out,
        "coverage": coverage.tolist(), "explored_final": res["explored_fraction"],
        "exploration_state": res["exploration_state"],
        "t90_s": t90, "reference": {"t90_s": ref_t90, "curve": [list(c) for c in ref_curve]},
        "t90_ratio": t90 / ref_t90 if np.isfinite(ref_t90) else float("nan"),
        "stuck_max_s": max(m["stuck_s"] for m in robots_out.values()),
        "still_max_s": max(m["still_s"] for m in robots_out.values()),
        "update_ms": latency_summary(ms) | {f"p{q}": float(np.percentile(ms, q)) if ms.size else float("nan")
                                            for q in (5, 25, 75, 99)},
        "counters": {k: res[k] for k in COUNTERS},
    }


def _worker_init() -> None:
    import cv2

    cv2.setNumThreads(1)


def _slug(world: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", world).strip("_")


def run_path(out: Path, world: str, seed: int, robots: int) -> Path:
    """The record of a run; its run folder is the same path without ``.json``."""
    return out / "runs" / f"{_slug(world)}__seed{seed}__robots{robots}.json"


def _write_json(path: Path, data: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".json.part")
    tmp.write_text(json.dumps(data, indent=1, default=float))
    tmp.replace(path)  # a sweep stopped mid-write leaves no half file


def _done(path: Path, request: dict) -> dict | None:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return data if data.get("request") == request else None


def sweep(worlds: list[str], seeds: list[int], robots: int, seconds: float | None, jobs: int, out: Path) -> list[dict]:
    """Every world × seed run (those already in ``out`` read back), in world, seed order."""
    tasks = [(w, s) for w in worlds for s in seeds]
    records: dict[tuple[str, int], dict] = {}
    todo = []
    for w, s in tasks:
        done = _done(run_path(out, w, s, robots), {"world": w, "seed": s, "robots": robots, "seconds": seconds})
        if done is not None:
            records[(w, s)] = done
        else:
            todo.append((w, s))
    bar = tqdm(total=len(tasks), initial=len(tasks) - len(todo), desc="sweep runs", unit="run")
    if jobs == 1:
        for w, s in todo:
            folder = run_path(out, w, s, robots).with_suffix("")
            records[(w, s)] = _finish(out, run_one(w, s, robots, seconds, folder), bar)
    elif todo:
        for v in _THREAD_VARS:  # each run single-threaded (the spawned workers read these at start)
            os.environ[v] = "1"
        with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn"), initializer=_worker_init) as ex:
            futures = {ex.submit(run_one, w, s, robots, seconds, run_path(out, w, s, robots).with_suffix("")): (w, s)
                       for w, s in todo}
            for f in as_completed(futures):
                records[futures[f]] = _finish(out, f.result(), bar)
    bar.close()
    return [records[t] for t in tasks]


def _finish(out: Path, record: dict, bar: tqdm) -> dict:
    _write_json(run_path(out, record["world"], record["seed"], len(record["robots"])), record)
    worst = max(r["ate_rmse_m"] for r in record["robots"].values())
    bar.set_postfix_str(f"{record['world']} s{record['seed']}: worst ATE {worst:.3f} m")
    bar.update()
    return record


def summarize(records: list[dict]) -> tuple[dict, list[str]]:
    """The criteria over all runs, and a row per run: (JSON summary, Markdown lines)."""
    robot_runs = [(r, name, m) for r in records for name, m in r["robots"].items()]
    ate = np.array([m["ate_rmse_m"] for _, _, m in robot_runs])
    ratio = np.array([m.get("ate_over_odom", np.nan) for _, _, m in robot_runs])
    met = (ate <= ATE_MAX) & (ratio <= RATIO_MAX)
    explore_ok = [r["t90_ratio"] <= TIME_FACTOR for r in records]
    stuck = [(r["world"], r["seed"], name, m["stuck_s"]) for r, name, m in robot_runs if m["stuck_s"] > STUCK_MAX]
    # records written before the body measure have no "still_s": nan, never counted as met
    still = [(r["world"], r["seed"], name, m.get("still_s", np.nan)) for r, name, m in robot_runs]
    summary = {
        "criteria": {"ate_max_m": ATE_MAX, "ratio_max": RATIO_MAX, "met_share": MET_SHARE, "median_max_m": MEDIAN_MAX,
                     "explored": EXPLORED, "time_factor": TIME_FACTOR, "stuck_radius_m": STUCK_RADIUS,
                     "stuck_max_s": STUCK_MAX},
        "robot_runs": len(robot_runs), "met": int(met.sum()), "met_fraction": float(met.mean()) if met.size else 0.0,
        "median_ate_m": float(np.median(ate)) if ate.size else float("nan"),
        "exploration_met": int(sum(explore_ok)), "runs": len(records),
        "exploration_failed": [{"world": r["world"], "seed": r["seed"], "t90_s": r["t90_s"],
                                "reference_t90_s": r["reference"]["t90_s"], "explored_final": r["explored_final"]}
                               for r, ok in zip(records, explore_ok) if not ok],
        "still_max_s": float(np.max([v for *_, v in still])) if still else 0.0,
        "still_over": [{"world": w, "seed": s, "robot": n, "still_s": v} for w, s, n, v in still
                       if not v <= STUCK_MAX],
        "stuck_max_s": max((m["stuck_s"] for _, _, m in robot_runs), default=0.0),
        "stuck_over": [{"world": w, "seed": s, "robot": n, "stuck_s": v} for w, s, n, v in stuck],
        "update_ms_p50_median": float(np.median([r["update_ms"]["p50"] for r in records])) if records else float("nan"),
        "update_ms_p95_max": max((r["update_ms"]["p95"] for r in records), default=float("nan")),
        "rows": [{k: r[k] for k in ("world", "kind", "size", "seed", "seconds", "explored_final", "t90_s", "t90_ratio",
                                    "stuck_max_s", "update_ms")}
                 | {"still_max_s": r.get("still_max_s", float("nan"))}
                 | {"reference_t90_s": r["reference"]["t90_s"],
                    "robots": {n: {k: m.get(k) for k in ("ate_rmse_m", "odom_ate_rmse_m", "ate_over_odom",
                                                         "still_s", "stuck_s")}
                               for n, m in r["robots"].items()}} for r in records],
    }
    yes = {True: "yes", False: "**no**"}
    slow = ", ".join(f"{f['world']} seed {f['seed']}" for f in summary["exploration_failed"])
    still_list = ", ".join(f"{s['world']} seed {s['seed']} {s['robot']} {s['still_s']:.0f} s"
                           for s in summary["still_over"])
    lines = [
        f"Closed loop over {len(records)} runs ({len({r['world'] for r in records})} worlds), "
        f"{len(records[0]['robots']) if records else 0} robots each.", "",
        f"- robot-runs with ATE ≤ {ATE_MAX:.2f} m and ≤ {RATIO_MAX:.0%} of odometry: {summary['met']} of "
        f"{summary['robot_runs']} ({summary['met_fraction']:.0%}; target ≥ {MET_SHARE:.0%}): "
        f"{yes[summary['met_fraction'] >= MET_SHARE]}",
        f"- median ATE {summary['median_ate_m']:.3f} m (target ≤ {MEDIAN_MAX:.2f} m): "
        f"{yes[summary['median_ate_m'] <= MEDIAN_MAX]}",
        f"- {EXPLORED:.0%} explored within {TIME_FACTOR:g}× the perfect-pose time: {summary['exploration_met']} of "
        f"{len(records)} runs" + (f"; not in {slow}" if slow else ""),
        f"- longest still (no point of the body moved {STUCK_RADIUS:g} m) {summary['still_max_s']:.1f} s "
        f"(target ≤ {STUCK_MAX:g} s): {yes[summary['still_max_s'] <= STUCK_MAX]}"
        + (f" ({still_list})" if still_list else ""),
        f"- longest stay (the position within {STUCK_RADIUS:g} m, turns on the spot included; the former "
        f"measure) {summary['stuck_max_s']:.1f} s, {len(summary['stuck_over'])} robot-runs above {STUCK_MAX:g} s",
        f"- filter step p50 {summary['update_ms_p50_median']:.1f} ms (median over runs), p95 up to "
        f"{summary['update_ms_p95_max']:.1f} ms", "",
        "| world | kind | size [m] | seed | ATE per robot [m] | ATE / odometry | met | explored | t90 / reference [s] "
        "| still / stay max [s] | step p50 / p95 [ms] |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in records:
        ms = list(r["robots"].values())
        nmet = sum(m["ate_rmse_m"] <= ATE_MAX and m.get("ate_over_odom", np.inf) <= RATIO_MAX for m in ms)
        lines.append(
            f"| {r['world']} | {r['kind']} | {r['size'][0]:g} × {r['size'][1]:g} | {r['seed']} | "
            + " / ".join(f"{m['ate_rmse_m']:.3f}" for m in ms) + " | "
            + " / ".join(f"{m.get('ate_over_odom', np.nan):.2f}" for m in ms) + f" | {nmet}/{len(ms)} | "
            f"{r['explored_final']:.0%} in {r['seconds']:.0f} s | {r['t90_s']:.0f} / {r['reference']['t90_s']:.0f} | "
            f"{r.get('still_max_s', np.nan):.1f} / {r['stuck_max_s']:.1f} | "
            f"{r['update_ms']['p50']:.1f} / {r['update_ms']['p95']:.1f} |")
    return summary, lines


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="mrslam experiment sweep", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--worlds", nargs="+", default=[], metavar="W",
                    help="world names: built-in, YAML paths, gen:KIND:SEED[:STARTS[:ROBOTS]]")
    ap.add_argument("--suite", type=positive_int, metavar="N",
                    help="add N generated worlds: office, ring, open, warehouse in turn, seeds 0..N-1, "
                         "start modes together/apart alternating")
    ap.add_argument("--seeds", type=non_negative_int, nargs="+", default=[0], metavar="S",
                    help="simulator and filter seeds (default 0)")
    ap.add_argument("--robots", type=positive_int, default=3, metavar="K",
                    help="team size: the worlds' first K start poses (default 3)")
    ap.add_argument("--seconds", type=positive_float, metavar="T",
                    help=f"simulated time per run (default {RUN_FACTOR:g} × the reference's time to "
                         f"{100 * EXPLORED:g} %%)")
    ap.add_argument("--jobs", type=positive_int, default=2, metavar="J", help="runs in parallel processes (default 2)")
    ap.add_argument("--out", default="runs/experiments/sweep", metavar="DIR")
    args = ap.parse_args(argv)
    worlds = list(dict.fromkeys(args.worlds + (suite(args.suite) if args.suite else [])))
    try:
        if not worlds:
            raise InputError("give --worlds or --suite")
        for w in worlds:  # every name and file checked before the first run
            have = len(load_world(w).start_poses)
            if have < args.robots:
                raise InputError(f"world {w} has {have} start poses, fewer than --robots {args.robots}")
    except InputError as exc:
        print(f"mrslam experiment sweep: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out)
    records = sweep(worlds, list(dict.fromkeys(args.seeds)), args.robots, args.seconds, args.jobs, out)
    summary, lines = summarize(records)
    md = write_tables(out, "sweep", "\n".join(lines), summary)
    for path in plot_all(records, summary, md.parent):
        print(f"wrote {path}")
    return 0
