"""The plots of ``mrslam experiment sweep``: ATE, ATE / odometry, explored fraction over time,
time stuck and filter step time, over its runs (records as ``sweep.run_one`` returns them)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def plot_all(records: list[dict], summary: dict, folder: Path) -> list[Path]:
    """Write sweep_ate.png, sweep_ratio.png, sweep_explored.png, sweep_stuck.png and
    sweep_latency.png into ``folder``; returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = summary["criteria"]
    labels = [f"{r['world']} s{r['seed']}" for r in records]
    paths = []

    def save(fig, name: str) -> None:
        fig.tight_layout()
        paths.append(folder / name)
        fig.savefig(paths[-1], dpi=110)
        plt.close(fig)

    for key, name, ylabel, lines in (
            ("ate_rmse_m", "sweep_ate.png", "ATE [m]",
             [(c["ate_max_m"], "target per robot", "tab:red"), (c["median_max_m"], "target median", "tab:orange")]),
            ("ate_over_odom", "sweep_ratio.png", "ATE / odometry ATE", [(c["ratio_max"], "target", "tab:red")])):
        fig, ax = plt.subplots(figsize=(8, 4.5))
        _by_kind(ax, records, key)
        for y, label, colour in lines:
            ax.axhline(y, color=colour, ls="--", lw=1, label=label)
        ax.set_ylabel(ylabel)
        ax.set_title(f"{ylabel} per robot-run, by kind of world")
        ax.legend(fontsize=8)
        ax.grid(True, axis="y", alpha=0.3)
        save(fig, name)

    fig, (ax, axn) = plt.subplots(1, 2, figsize=(13, 4.8))
    colours = plt.cm.tab20(np.r_[0:20:2, 1:20:2][np.arange(len(records)) % 20])  # the dark ones first
    for r, label, col in zip(records, labels, colours):
        cov = np.asarray(r["coverage"], float).reshape(-1, 2)
        ref = r["reference"]["t90_s"]
        ax.plot(cov[:, 0], cov[:, 1], color=col, lw=1.2, label=label)
        if np.isfinite(ref):
            ax.plot([ref], [c["explored"]], "x", color=col, ms=7)
            ax.plot([c["time_factor"] * ref], [c["explored"]], "|", color=col, ms=14, mew=2)
            axn.plot(cov[:, 0] / ref, cov[:, 1], color=col, lw=1.2)
    ax.axhline(c["explored"], color="grey", ls=":", lw=1)
    ax.set_xlabel("simulated time [s]")
    ax.set_ylabel("explored fraction of the reachable free area")
    ax.set_title("closed loop (x: perfect-pose time to 90 %, |: 1.5× it)")
    ax.legend(fontsize=6, ncol=2)
    axn.axhline(c["explored"], color="grey", ls=":", lw=1)
    axn.axvline(c["time_factor"], color="tab:red", ls="--", lw=1, label=f"{c['time_factor']:g}× the reference")
    axn.set_xlabel("time / perfect-pose time to 90 %")
    axn.set_title("against the perfect-pose reference")
    axn.legend(fontsize=8)
    for a in (ax, axn):
        a.set_ylim(0, 1.02)
        a.grid(True, alpha=0.3)
    save(fig, "sweep_explored.png")

    fig, ax = plt.subplots(figsize=(9, 0.9 + 0.28 * len(records)))
    y = np.arange(len(records))
    for k, r in enumerate(records):
        still = [m.get("still_s", np.nan) for m in r["robots"].values()]
        stay = [m["stuck_s"] for m in r["robots"].values()]
        ax.plot(stay, [k] * len(stay), "o", mfc="none", color="tab:grey", ms=5,
                label="position within the radius (turns on the spot count)" if k == 0 else None)
        ax.plot(still, [k] * len(still), "o", color="tab:blue", ms=4,
                label="no point of the body moved the radius" if k == 0 else None)
    ax.axvline(c["stuck_max_s"], color="tab:red", ls="--", lw=1, label="target")
    ax.set_yticks(y, labels, fontsize=7)
    ax.invert_yaxis()
    ax.set_xlabel(f"longest time a robot stood, radius {c['stuck_radius_m']:g} m [s] (a dot per robot)")
    ax.legend(fontsize=8)
    ax.grid(True, axis="x", alpha=0.3)
    save(fig, "sweep_stuck.png")

    fig, ax = plt.subplots(figsize=(2.5 + 0.35 * len(records), 5))
    stats = [{"label": label, "med": r["update_ms"]["p50"], "q1": r["update_ms"]["p25"], "q3": r["update_ms"]["p75"],
              "whislo": r["update_ms"]["p5"], "whishi": r["update_ms"]["p95"], "fliers": [r["update_ms"]["max"]]}
             for r, label in zip(records, labels)]
    ax.bxp(stats, showfliers=True)
    ax.set_yscale("log")
    ax.tick_params(axis="x", labelsize=7, labelrotation=90)
    ax.set_ylabel("central filter step [ms]")
    ax.set_title("box p25-p75, whiskers p5-p95, dot: max", fontsize=9)
    ax.grid(True, axis="y", alpha=0.3)
    save(fig, "sweep_latency.png")
    return paths


def _by_kind(ax, records: list[dict], key: str) -> None:
    """A box of ``key`` over the robot-runs of each kind of world, every robot-run a dot."""
    kinds = sorted({r["kind"] for r in records})
    values = [[m.get(key, np.nan) for r in records if r["kind"] == k for m in r["robots"].values()] for k in kinds]
    ax.boxplot(values, showfliers=False)
    rng = np.random.default_rng(0)
    for k, v in enumerate(values, start=1):
        ax.plot(k + rng.uniform(-0.15, 0.15, len(v)), v, "o", color="tab:blue", ms=3, alpha=0.7)
    ax.set_xticks(np.arange(1, len(kinds) + 1), [f"{k} ({len(v)})" for k, v in zip(kinds, values)])

