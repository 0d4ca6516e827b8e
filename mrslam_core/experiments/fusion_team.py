"""``mrslam experiment fusion_team``: the simulated team with robots whose start pose is unknown.

For every world × seed, ``mrslam team``'s closed loop (``pipelines.team.run``, the team defaults,
``--robots`` robots) twice: with every start pose known, and with the robots of ``--unknown``
(default all but robot1) in ``unknown_start``. Each of those explores alone in its own start frame
until the central mapper joins it (map alignment through the evidence gate, or a rendezvous), then
with the team. Reported per robot with an unknown start: when and how it joined, the join
transform's error against its true start pose (the transform maps its start frame into the map
frame, so it IS its start pose), and its ATE from the join to the end against the known-start
run's over the same window; the known robots' whole-run ATE in both runs; the explored fraction.

Writes ``fusion_team.md`` and ``fusion_team.json`` under ``--out``.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace

import numpy as np

from mrslam_core.configio import non_negative_int, positive_float, positive_int
from mrslam_core.evaluation.metrics import ate_rmse
from mrslam_core.experiments._output import write_tables
from mrslam_core.experiments.sweep import _THREAD_VARS, _worker_init, team_config
from mrslam_core.geometry.se2 import wrap_angle
from mrslam_core.pipelines.team import run as run_team
from mrslam_core.sim.world import load_world
from mrslam_core.sim.worldgen import suite


def run_pair(world: str, seed: int, robots: int, seconds: float, unknown: tuple[str, ...]) -> dict:
    """The known-start and the unknown-start run of one world and seed, reduced to what the table
    needs (JSON-ready)."""
    cfg = replace(team_config(world, seed, robots), seconds=seconds)
    starts = np.asarray(load_world(world).start_poses, float)[:robots]
    out = {"world": world, "seed": seed}
    for label, c in (("known", cfg), ("unknown", replace(cfg, unknown_start=unknown))):
        res = run_team(c)
        out[label] = {
            "explored": res["explored_fraction"], "unmerged": res["unmerged"],
            "merges": [{k: m[k] for k in ("robot", "stamp_ns", "via", "accepted", "reason", "transform") if k in m}
                       for m in res["merges"]],
            "trajectories": {n: {k: tr[k].tolist() for k in ("t", "est", "gt")}
                             for n, tr in res["trajectories"].items()},
        }
    rows = {}
    for i, name in enumerate(f"robot{k + 1}" for k in range(robots)):
        kn = out["known"]["trajectories"][name]
        un = out["unknown"]["trajectories"].get(name)
        joins = [m for m in out["unknown"]["merges"] if m["robot"] == name and m["accepted"]]
        row = {"unknown_start": name in unknown, "joined_s": None, "via": None}
        if joins:
            t_join = joins[0]["stamp_ns"] * 1e-9
            err = np.asarray(joins[0]["transform"]) - starts[i]
            row |= {"joined_s": t_join, "via": joins[0]["via"], "join_error_m": float(np.hypot(*err[:2])),
                    "join_error_deg": float(np.degrees(abs(wrap_angle(err[2]))))}
        t_from = row["joined_s"] or 0.0
        if un is not None and len(un["t"]):
            window = np.asarray(kn["t"]) >= t_from
            row["ate_m"] = ate_rmse(np.asarray(un["est"]), np.asarray(un["gt"]))
            row["known_ate_m"] = ate_rmse(np.asarray(kn["est"])[window], np.asarray(kn["gt"])[window])
            row["ratio"] = row["ate_m"] / max(row["known_ate_m"], 1e-12)
        rows[name] = row
    out["robots"] = rows
    return out


def _fmt(v, spec: str = ".3f") -> str:
    """A number for the table, or a dash for none."""
    return "–" if v is None else format(v, spec)


def table(records: list[dict]) -> str:
    """The Markdown table of :func:`run_pair` records: a row per robot, then how many robots with an
    unknown start joined and the median and count within 1.5× of their ATE ratios."""
    lines = ["| world | seed | robot | start | joined at [s], how | join error [m, °] | ATE from the join, "
             "unknown / known start [m] | ratio | explored unknown / known |",
             "|---|---|---|---|---|---|---|---|---|"]
    ratios = []
    for rec in records:
        for name, r in rec["robots"].items():
            how = "–" if r["joined_s"] is None else f"{r['joined_s']:.1f}, {r['via']}"
            err = "" if r["joined_s"] is None else f"{r['join_error_m']:.3f}, {r['join_error_deg']:.2f}"
            if r["unknown_start"] and "ratio" in r:
                ratios.append(r["ratio"])
            lines.append(
                f"| {rec['world']} | {rec['seed']} | {name} | {'unknown' if r['unknown_start'] else 'known'} | {how} | "
                f"{err} | {_fmt(r.get('ate_m'))} / {_fmt(r.get('known_ate_m'))} | {_fmt(r.get('ratio'), '.2f')} | "
                f"{rec['unknown']['explored']:.0%} / {rec['known']['explored']:.0%} |")
    n_unknown = sum(r["unknown_start"] for rec in records for r in rec["robots"].values())
    joined = sum(r["unknown_start"] and r["joined_s"] is not None for rec in records for r in rec["robots"].values())
    summary = f"\n{joined} of {n_unknown} robots with an unknown start joined"
    if ratios:
        summary += (f"; ATE after the join over the known-start run's: median {np.median(ratios):.2f}, "
                    f"{sum(x <= 1.5 for x in ratios)} of {len(ratios)} within 1.5×")
    return "\n".join(lines) + summary


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="mrslam experiment fusion_team", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--worlds", nargs="+", default=[], metavar="W", help="world names (see mrslam experiment sweep)")
    ap.add_argument("--suite", type=positive_int, metavar="N", help="add N generated worlds (worldgen.suite)")
    ap.add_argument("--seeds", type=non_negative_int, nargs="+", default=[0], metavar="S")
    ap.add_argument("--robots", type=positive_int, default=3, metavar="K")
    ap.add_argument("--unknown", nargs="+", metavar="ROBOT",
                    help="robots with an unknown start (default: all but robot1)")
    ap.add_argument("--seconds", type=positive_float, default=60.0, metavar="T", help="simulated seconds per run")
    ap.add_argument("--jobs", type=positive_int, default=2, metavar="J", help="world × seed pairs in parallel")
    ap.add_argument("--out", default="runs/experiments/fusion_team", metavar="DIR")
    args = ap.parse_args(argv)
    worlds = list(args.worlds) + (suite(args.suite) if args.suite else [])
    if not worlds:
        ap.error("give --worlds or --suite")
    unknown = tuple(args.unknown or [f"robot{k + 1}" for k in range(1, args.robots)])
    tasks = [(w, s, args.robots, args.seconds, unknown) for w in worlds for s in args.seeds]
    if args.jobs == 1:
        records = [run_pair(*t) for t in tasks]
    else:
        for v in _THREAD_VARS:
            os.environ[v] = "1"
        with ProcessPoolExecutor(args.jobs, mp_context=multiprocessing.get_context("spawn"),
                                 initializer=_worker_init) as ex:
            records = list(ex.map(run_pair, *zip(*tasks)))
    write_tables(args.out, "fusion_team", table(records), records)
    return 0
