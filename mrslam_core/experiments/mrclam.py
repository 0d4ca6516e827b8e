"""``mrslam experiment mrclam DIR``: the MR.CLAM accuracy table of docs/results.md.

Runs, over several seeds, the joint filter with robot-to-robot measurements, the joint filter
without them, and five independent single-robot filters with the same particle count, and prints
per-robot ATE against Vicon next to dead reckoning.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from mrslam_core.datasets.mrclam import MrclamDataset
from mrslam_core.evaluation.report import robot_metrics
from mrslam_core.experiments._output import write_tables
from mrslam_core.pipelines.mrclam import MrclamConfig, run

VARIANTS = {
    "joint + sightings": {},
    "joint, no sightings": {"use_sightings": False},
    "independent": {"mode": "independent"},
}


def evaluate(ds: MrclamDataset, cfg: MrclamConfig) -> dict:
    """Per-robot metrics and mean step time of one run."""
    res = run(ds, cfg)
    robots = {n: robot_metrics(tr) for n, tr in res["trajectories"].items()}
    return {"robots": robots, "step_ms_p50": float(np.median(res["update_ms"]))}


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="mrslam experiment mrclam", description=__doc__)
    ap.add_argument("folder", help="MR.CLAM dataset folder, e.g. ../shared/data/mrclam/dataset6")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--particles", type=int)
    ap.add_argument("--out", default="runs/experiments")
    args = ap.parse_args(argv)
    ds = MrclamDataset(args.folder)
    base = MrclamConfig()
    if args.particles:
        base = replace(base, filter=replace(base.filter, num_particles=args.particles))
    table: dict[str, list[dict]] = {}
    for name, change in VARIANTS.items():
        table[name] = []
        for seed in range(args.seeds):
            cfg = replace(base, **change, filter=replace(base.filter, seed=seed))
            table[name].append(evaluate(ds, cfg))
            r = table[name][-1]["robots"]
            print(f"{name:22s} seed {seed}: " + " ".join(f"{k} {v['ate_rmse_m']:.3f}" for k, v in r.items()), flush=True)
    robots = list(table["joint + sightings"][0]["robots"])
    lines = [
        f"MR.CLAM {args.folder}, M = {base.filter.num_particles}, {args.seeds} seeds; ATE RMSE [m] "
        "mean (max) over seeds; odometry = dead reckoning",
        "",
        "| variant | " + " | ".join(robots) + " | mean |",
        "|---|" + "---|" * (len(robots) + 1),
    ]
    odo = [table["joint + sightings"][0]["robots"][r]["odom_ate_rmse_m"] for r in robots]
    lines.append("| odometry | " + " | ".join(f"{o:.3f}" for o in odo) + f" | {np.mean(odo):.3f} |")
    summary = {}
    for name, runs in table.items():
        ate = np.array([[r["robots"][k]["ate_rmse_m"] for k in robots] for r in runs])
        summary[name] = {"mean_per_robot": ate.mean(0).tolist(), "max_per_robot": ate.max(0).tolist(),
                         "mean": float(ate.mean())}
        cells = [f"{m:.3f} ({x:.3f})" for m, x in zip(ate.mean(0), ate.max(0))]
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {ate.mean():.3f} |")
    text = "\n".join(lines)
    write_tables(args.out, "mrclam", text, {"runs": table, "summary": summary})
    return 0
