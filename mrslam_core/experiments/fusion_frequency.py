"""``mrslam experiment fusion_frequency``: how often to fuse (004 section 5, its figure 7).

Two robots with unknown relative start poses on the synthetic stereo world
(:mod:`mrslam_core.datasets.synthetic`), each with its own FastSLAM filter of B particles from its
own origin, for ``steps`` iterations (004: B = 50, 700 iterations). Fusion is attempted every F
iterations (F = 50, 100, 300) or only at the end: at an attempt the two best maps are aligned
(RANSAC) and, if accepted, robot 2's filter is joined into robot 1's particle by particle; from then
on both robots are robots of that one filter and map into one shared map (later attempts have
nothing left to fuse). "Only at the end" keeps the filters apart and joins them after the last
iteration. At the end, the landmarks of the final best map of each variant are compared with those
of the end-only map by their true identity (the track id that created them), and the share of
common landmarks whose uncertainty (trace and determinant of the covariance) is smaller than in the
end-only map is reported (004: 69 % for fusion every 300 iterations).
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from mrslam_core.datasets.synthetic import SyntheticWorld, SyntheticWorldConfig
from mrslam_core.experiments._output import write_tables
from mrslam_core.fusion.config import FusionConfig
from mrslam_core.fusion.join import try_join
from mrslam_core.slam.config import FilterConfig
from mrslam_core.slam.filter import MultiRobotFastSLAM


def landmark_uncertainty(slam: MultiRobotFastSLAM) -> dict[int, tuple[float, float]]:
    """Track id -> (trace [m²], determinant [m⁶]) of the covariance of the landmark created for
    it, in the best particle (the slot with most observations when there are several)."""
    slots, _, cov, _, count = slam.best_map()
    origin = slam.landmarks.origin[slots]
    out: dict[int, tuple[float, float, int]] = {}
    for o, c, n in zip(origin, cov, count):
        if o < 0:
            continue
        if int(o) not in out or n > out[int(o)][2]:
            out[int(o)] = (float(np.trace(c)), float(np.linalg.det(c)), int(n))
    return {k: v[:2] for k, v in out.items()}


def run_variant(
    world_cfg: SyntheticWorldConfig, filter_cfg: FilterConfig, fusion: FusionConfig, steps: int,
    every: int | None,
) -> dict:
    """Two robots, local filters, fusion attempted every ``every`` steps (None: only at the end).

    Returns:
        {"joined_at": step or None, "uncertainty": {track id: (trace, det)}, "attempts": [...],
         "pose_rmse_m": robot 2's position RMSE after joining (None if joined at the end)}
    """
    world = SyntheticWorld(world_cfg)
    starts = world.start_poses()
    central = MultiRobotFastSLAM(filter_cfg, ["robot1"], starts[:1])
    local: MultiRobotFastSLAM | None = MultiRobotFastSLAM(
        replace(filter_cfg, seed=filter_cfg.seed + 1), ["robot2"], np.zeros((1, 3))
    )
    joined_at = None
    attempts = []
    err = []
    for i, (_, true, _, updates) in enumerate(world.run(steps), start=1):
        if local is None:
            central.step(updates)
            err.append(float(np.linalg.norm(central.estimate().poses[1, :2] - true[1, :2])))
            continue
        central.step(updates[:1])
        local.step(updates[1:])
        if (every is not None and i % every == 0) or i == steps:
            al, joined = try_join(central, local, fusion)
            attempts.append(f"{i}: " + ("joined" if joined else al.reason))
            if joined is not None:
                joined_at = i
                local = None
    return {
        "joined_at": joined_at, "uncertainty": landmark_uncertainty(central), "attempts": attempts,
        "pose_rmse_m": float(np.sqrt(np.mean(np.square(err)))) if err else None,
    }


def shares(variant: dict, end_only: dict) -> dict:
    """Shares of the common landmarks whose uncertainty is lower / higher than in the end-only
    map (trace and determinant); landmarks seen only before the variant's fusion are identical
    in both runs (same data, same seeds) and counted as unchanged. ``lower_of_changed`` is
    lower / (lower + higher), the quantity of 004 fig. 7."""
    common = sorted(set(variant["uncertainty"]) & set(end_only["uncertainty"]))
    if not common:
        return {"common": 0}
    a = np.array([variant["uncertainty"][k] for k in common])
    b = np.array([end_only["uncertainty"][k] for k in common])
    out: dict = {"common": len(common), "median_trace_ratio": float(np.median(a[:, 0] / b[:, 0]))}
    for j, name in ((0, "trace"), (1, "det")):
        rel = a[:, j] / b[:, j]
        lower, higher = rel < 1 - 1e-6, rel > 1 + 1e-6
        out[f"lower_{name}"] = float(lower.mean())
        out[f"higher_{name}"] = float(higher.mean())
        out[f"lower_of_changed_{name}"] = float(lower.sum() / max(lower.sum() + higher.sum(), 1))
    return out


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="mrslam experiment fusion_frequency", description=__doc__)
    ap.add_argument("--steps", type=int, default=700)
    ap.add_argument("--particles", type=int, default=50)
    ap.add_argument("--periods", default="50,100,300", help="fusion periods in iterations")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--out", default="runs/experiments")
    args = ap.parse_args(argv)
    periods = [int(p) for p in args.periods.split(",")]
    results = []
    for seed in range(args.seeds):
        world_cfg = SyntheticWorldConfig(seed=seed, num_robots=2, sigma_d=1.0, sigma_r=10.0, sigma_c=10.0)
        filter_cfg = FilterConfig(num_particles=args.particles, seed=seed)
        fusion = FusionConfig(seed=seed)
        end = run_variant(world_cfg, filter_cfg, fusion, args.steps, None)
        row = {"seed": seed, "end_only": {"joined_at": end["joined_at"], "landmarks": len(end["uncertainty"])}}
        for p in periods:
            v = run_variant(world_cfg, filter_cfg, fusion, args.steps, p)
            row[str(p)] = {"joined_at": v["joined_at"], "pose_rmse_m": v["pose_rmse_m"], **shares(v, end)}
            print(f"seed {seed} every {p}: joined at {v['joined_at']}, {row[str(p)]}", flush=True)
        results.append(row)
    lines = [
        (f"Fusion frequency (004 fig. 7): 2 robots, synthetic stereo world, B = {args.particles}, "
        f"{args.steps} iterations, {args.seeds} seeds. Share of the landmarks common to both maps "
        "whose covariance is smaller than with fusion only at the end."),
        "",
        "| seed | fusion every | joined at | common landmarks | lower / higher / same (trace) | lower of changed: trace, det | median trace ratio | robot 2 RMSE after join [m] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in results:
        for p in periods:
            r = row[str(p)]
            if not r.get("common"):
                lines.append(f"| {row['seed']} | {p} | {r['joined_at']} | 0 | | | | |")
                continue
            same = max(0.0, 1 - r["lower_trace"] - r["higher_trace"])
            rm = "" if r["pose_rmse_m"] is None else f"{r['pose_rmse_m']:.3f}"
            lines.append(
                f"| {row['seed']} | {p} | {r['joined_at']} | {r['common']} | {100 * r['lower_trace']:.0f} / "
                f"{100 * r['higher_trace']:.0f} / {100 * same:.0f} % | {100 * r['lower_of_changed_trace']:.0f} %, "
                f"{100 * r['lower_of_changed_det']:.0f} % | {r['median_trace_ratio']:.2f} | {rm} |"
            )
    text = "\n".join(lines)
    write_tables(args.out, "fusion_frequency", text, results)
    return 0
