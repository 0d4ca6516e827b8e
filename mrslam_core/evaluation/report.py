"""The run folder every command writes: report.json, TUM trajectories, plots, effective config."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from mrslam_core.configio import to_dict, write_yaml
from mrslam_core.evaluation.metrics import ate_rmse, heading_rmse, rpe_rmse
from mrslam_core.evaluation.plots import plot_run
from mrslam_core.evaluation.tum import write_tum
from mrslam_core.exploration.mapfile import save_map_file


def latency_summary(ms: np.ndarray) -> dict[str, float]:
    """p50, p95, max and mean of step times [ms]."""
    ms = np.asarray(ms, float)
    if ms.size == 0:
        return {"p50": float("nan"), "p95": float("nan"), "max": float("nan"), "mean": float("nan"), "count": 0}
    return {
        "p50": float(np.percentile(ms, 50)), "p95": float(np.percentile(ms, 95)),
        "max": float(ms.max()), "mean": float(ms.mean()), "count": int(ms.size),
    }


def robot_metrics(tr: dict) -> dict[str, float]:
    """ATE/RPE/heading of estimate and odometry against ground truth at the same stamps."""
    out: dict[str, float] = {"poses": int(len(tr["t"]))}
    if tr.get("gt") is None:
        return out
    out["ate_rmse_m"] = ate_rmse(tr["est"], tr["gt"])
    out["rpe_rmse_m"] = rpe_rmse(tr["t"], tr["est"], tr["gt"])
    out["heading_rmse_rad"] = heading_rmse(tr["est"], tr["gt"])
    if tr.get("odom") is not None:
        out["odom_ate_rmse_m"] = ate_rmse(tr["odom"], tr["gt"])
        out["odom_rpe_rmse_m"] = rpe_rmse(tr["t"], tr["odom"], tr["gt"])
        out["ate_over_odom"] = out["ate_rmse_m"] / max(out["odom_ate_rmse_m"], 1e-12)
    return out


def corrections(report: dict) -> dict[str, list[tuple[float, str]]]:
    """robot -> [(time [s], cause)] of the accepted pose corrections a report lists: its
    ``relocalizations`` (after a gap, by the map check) and its accepted ``merges``."""
    out: dict[str, list[tuple[float, str]]] = {}
    entries = list(report.get("relocalizations") or []) + [dict(m, cause="merge") for m in report.get("merges") or []]
    for e in entries:
        if isinstance(e, dict) and e.get("accepted") and "robot" in e and "stamp_ns" in e:
            out.setdefault(str(e["robot"]), []).append((int(e["stamp_ns"]) * 1e-9, str(e.get("cause", ""))))
    return {r: sorted(v) for r, v in out.items()}


def write_run(
    out: str | Path,
    trajectories: dict[str, dict],
    config: Any,
    update_ms: np.ndarray,
    landmarks: dict | None = None,
    truth_landmarks: np.ndarray | None = None,
    extra: dict | None = None,
    plots: bool = True,
    occupancy: dict | None = None,
) -> dict:
    """Write the run folder and return the report.

    Args:
        out: folder to write into.
        trajectories: robot -> {"t": (N,) [s], "est": (N, 3), "gt": (N, 3) | None, "odom": (N, 3) | None}.
        config: the effective config (a dataclass), written as config.yaml and into the report.
        update_ms: (S,) central filter step times [ms].
        landmarks: best particle's map {"mean": (L, dim), "cov": (L, dim, dim)}.
        truth_landmarks: (T, 2) ground-truth landmark positions for the map plot.
        extra: more top-level report entries.
        occupancy: the final occupancy grid (see :func:`plot_run`; optional "free_thresh" and
            "occupied_thresh"), plotted as occupancy.png and written as occupancy.yaml + .pgm in
            the ROS map_server format.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for name, tr in trajectories.items():
        for kind in ("est", "gt", "odom"):
            if tr.get(kind) is not None:
                write_tum(out / "trajectories" / f"{name}_{kind}.tum", tr["t"], tr[kind])
    report = {
        "robots": {name: robot_metrics(tr) for name, tr in sorted(trajectories.items())},
        "landmarks": int(len(landmarks["mean"])) if landmarks is not None else 0,
        "update_ms": latency_summary(update_ms),
        "config": to_dict(config),
    }
    report.update(extra or {})
    if occupancy is not None:
        thresholds = {k: occupancy[k] for k in ("free_thresh", "occupied_thresh") if k in occupancy}
        save_map_file(out / "occupancy.yaml", occupancy["probability"], occupancy["known"], occupancy["origin"],
                      occupancy["resolution"], **thresholds)
        report["occupancy_map"] = "occupancy.yaml"
    if plots:
        report["plots"] = [p.name for p in plot_run(out, trajectories, landmarks, truth_landmarks, occupancy,
                                                     corrections(report))]
    write_yaml(config, out / "config.yaml")
    (out / "report.json").write_text(json.dumps(report, indent=2, default=float))
    return report
