"""``mrslam experiment fusion_mrclam DIR``: MR.CLAM with robots whose start pose is unknown (issue 8).

The log goes through the central mapper as in ``mrslam mrclam``
(:func:`mrslam_core.pipelines.mrclam.run`), with every robot but the ``known`` ones in
``unknown_start``: robot 1 starts the central filter at its Vicon start pose, every other robot is
mapped by its own local filter from its own origin until its :class:`~mrslam_core.pipelines.central.
lifecycle.Lifecycle` joins it, particle by particle (004 section 5), either by a rendezvous — it and
a robot of the central filter read each other within ``fusion.sighting_pair_window``, which gives
its pose in the common frame directly (:mod:`mrslam_core.fusion.rendezvous`), once a second such
sighting or an alignment agrees — or, every ``merge_every`` of its sets, by aligning its best map
with the central best map (barcode descriptors, the χ² tests of
:mod:`mrslam_core.fusion.acceptance`). From then on it is one more robot of the joint filter.

Reported per merged robot: the merge time and how, the transform's error against the robot's true
start pose, and its ATE against Vicon from the merge to the end, next to the ATE of the known-start
run (:func:`mrslam_core.pipelines.mrclam.run` with the same config) over the SAME time window, both
unaligned and after one SE(2) transform fitted to the whole team.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass, field, replace

import numpy as np

from mrslam_core.datasets.mrclam import MrclamDataset
from mrslam_core.evaluation.metrics import ate_rmse
from mrslam_core.experiments._output import write_tables
from mrslam_core.fusion.alignment import alignment_error, apply_transform, rigid_transform_2d
from mrslam_core.fusion.config import FusionConfig
from mrslam_core.pipelines.mrclam import MrclamConfig, robot_number
from mrslam_core.pipelines.mrclam import run as run_mapper
from mrslam_core.slam.config import FilterConfig


def _mrclam_fusion() -> FusionConfig:
    # 15 landmarks with unique barcodes: a descriptor match is the same landmark, so a match
    # that is not an inlier is a badly mapped landmark of the robot's own map (dropped). The
    # joined robot's local particles agree on their pose relative to their own map far more than
    # the alignment fixes it, so the alignment's covariance goes into the joined robot's
    # FastSLAM 2.0 proposal and the moved landmarks' covariances (docs/fusion.md), not into
    # per-particle transform draws; an alignment whose error the joined cloud cannot hold then
    # waits for a sighting that agrees.
    return FusionConfig(source_outliers="drop", transform_uncertainty="proposal")


def pinned_filter() -> FilterConfig:
    """The earlier MR.CLAM filter (heading / position random walks 0.05 rad/√s and 0.005 m/√s,
    motion noise sampled every step, no re-localisation; ``--filter pinned``), which this
    experiment used before robots could join by rendezvous. The current defaults (deferred motion
    noise, re-localisation) are the ones of docs/results.md, "Multi-robot FastSLAM on real data:
    UTIAS MR.CLAM dataset 6". With map alignment only the current defaults did worse; with
    rendezvous joins they do better (docs/fusion.md, "Measured, not adopted")."""
    base = MrclamConfig().filter
    return replace(
        base,
        motion=replace(base.motion, sigma_xy_rw=0.005, sigma_theta_rw=0.05),
        defer_motion_noise=False,
        relocalization=replace(base.relocalization, enabled=False),
    )


@dataclass(frozen=True)
class MrclamFusionConfig:
    """The unknown-start MR.CLAM run.

    Attributes:
        mrclam: the mapper and filter, by default the MR.CLAM profile (the known-start run it is
            compared with uses the same); its ``merge_every`` sets how often a local map is
            aligned.
        fusion: alignment and join tests of the unknown-start run.
        known: robots whose start pose is known (they start the central filter).
        rendezvous: also join a robot on mutual sightings (``CentralConfig.rendezvous``), and
            hold a weak alignment until a sighting agrees.
    """

    mrclam: MrclamConfig = field(default_factory=MrclamConfig)
    fusion: FusionConfig = field(default_factory=_mrclam_fusion)
    known: tuple[int, ...] = (1,)
    rendezvous: bool = True

    def unknown_start_config(self) -> MrclamConfig:
        """The mapper's config of the unknown-start run."""
        mc = self.mrclam
        if not any(robot_number(r) in self.known for r in mc.robots):
            raise ValueError("at least one robot must have a known start pose")
        return replace(mc, unknown_start=tuple(r for r in mc.robots if robot_number(r) not in self.known),
                       rendezvous=self.rendezvous, fusion=self.fusion)


def run_unknown_start(ds: MrclamDataset, cfg: MrclamFusionConfig, progress: bool = False) -> dict:
    """The log through the central mapper with the robots not in ``cfg.known`` in ``unknown_start``.

    Returns:
        {"times": (S+1,) [s], "est": {robot: (S+1, 3) map-frame estimate, NaN before merging},
         "gt": {robot: (S+1, 3)}, "merged": {robot: {"step", "time_s", "via", "transform",
         "inliers", "rmse_m", "start_error_m", "start_error_deg", "fused", "added", "dropped",
         "join_pose_error_m"}}, "attempts": {robot: [reasons]}, "update_ms": (S,)}
    """
    mc = cfg.unknown_start_config()
    res = run_mapper(ds, mc, progress)
    traj = res["trajectories"]
    times = traj[mc.robots[0]]["t"]
    t0 = times[0]
    merged: dict[str, dict] = {}
    attempts: dict[str, list[str]] = {r: [] for r in mc.unknown_start}
    for m in res["merges"]:
        r = m["robot"]
        if not m["accepted"]:
            attempts[r].append(f"{m['stamp_ns'] * 1e-9:.1f} s: {m['via']}: {m['reason']}")
            continue
        est, gt = traj[r]["est"], traj[r]["gt"]
        k = int(np.flatnonzero(np.isfinite(est[:, 0]))[0])
        dt, dth = alignment_error(np.asarray(m["transform"]), gt[0])
        merged[r] = {"step": k, "time_s": float(times[k] - t0), "via": "map alignment" if m["via"] == "alignment"
                     else m["via"], "transform": m["transform"], "inliers": m["inliers"], "rmse_m": m["rmse_m"],
                     "start_error_m": dt, "start_error_deg": float(np.degrees(dth)), "fused": m["fused"],
                     "added": m["added"], "dropped": m["dropped"],
                     "join_pose_error_m": float(np.linalg.norm(est[k, :2] - gt[k, :2]))}
    return {"times": times, "est": {r: v["est"] for r, v in traj.items()}, "gt": {r: v["gt"] for r, v in traj.items()},
            "merged": merged, "attempts": attempts, "update_ms": res["update_ms"]}


def gauge_free(
    est: dict[str, np.ndarray], gt: dict[str, np.ndarray], first: dict[str, int]
) -> tuple[dict[str, float], np.ndarray]:
    """Per-robot ATE [m] after ONE rigid 2D transform fitted to all robots' estimated positions
    from their ``first`` step on (the team's common frame, which only the known robots' start
    poses anchor, removed; each robot's own error is kept).

    Args:
        est, gt: robot -> (S+1, 3) map-frame estimates (NaN before merging) and ground truth.
        first: robot -> first step to use.

    Returns:
        (robot -> ATE [m], the fitted transform (tx [m], ty [m], θ [rad]) estimate -> Vicon).
    """
    e = np.concatenate([est[r][first[r]:, :2] for r in first])
    g = np.concatenate([gt[r][first[r]:, :2] for r in first])
    ok = np.isfinite(e).all(1)
    t = rigid_transform_2d(e[ok], g[ok])
    out = {}
    for r, k in first.items():
        d = apply_transform(t, est[r][k:, :2]) - gt[r][k:, :2]
        out[r] = float(np.sqrt(np.mean((d**2).sum(1))))
    return out, t


def compare(ds: MrclamDataset, cfg: MrclamFusionConfig, progress: bool = False) -> dict:
    """The unknown-start run and the known-start run with the same config, per robot: ATE from
    the merge to the end in both (same window) and their ratio, raw (map frame) and gauge-free
    (:func:`gauge_free`, one rigid transform for the whole team, fitted per run)."""
    tic = time.perf_counter()
    unknown = run_unknown_start(ds, cfg, progress)
    t_unknown = time.perf_counter() - tic
    tic = time.perf_counter()
    known = run_mapper(ds, cfg.mrclam)
    t_known = time.perf_counter() - tic
    known_names = [f"robot{i}" for i in cfg.known]
    first = {r: unknown["merged"][r]["step"] if r in unknown["merged"] else 0
             for r in unknown["gt"] if r in unknown["merged"] or r in known_names}
    ks = {r: known["trajectories"][r]["est"] for r in unknown["gt"]}
    free_u, gauge_u = gauge_free(unknown["est"], unknown["gt"], first)
    free_k, gauge_k = gauge_free(ks, unknown["gt"], first)
    rows = {}
    for rname, gt in unknown["gt"].items():
        row: dict = {"ate_known_start_full_m": ate_rmse(ks[rname], gt)}
        if rname in first:
            sl = slice(first[rname], None)
            row["merged_at_s"] = float(unknown["times"][first[rname]] - unknown["times"][0])
            row["ate_m"] = ate_rmse(unknown["est"][rname][sl], gt[sl])
            row["ate_known_start_m"] = ate_rmse(ks[rname][sl], gt[sl])
            row["ratio"] = row["ate_m"] / row["ate_known_start_m"]
            row["gauge_free_ate_m"] = free_u[rname]
            row["gauge_free_ate_known_start_m"] = free_k[rname]
            row["gauge_free_ratio"] = free_u[rname] / free_k[rname]
        rows[rname] = row
    return {"robots": rows, "merged": unknown["merged"], "attempts": unknown["attempts"],
            "gauge": {"unknown_start": gauge_u.tolist(), "known_start": gauge_k.tolist()},
            "seconds": {"unknown_start": t_unknown, "known_start": t_known},
            "step_ms_p50": float(np.median(unknown["update_ms"]))}


class LaterStart:
    """A dataset whose time span starts ``start`` [s] later (every robot's start pose, known or
    not, is then its pose there): the same arena and robots in another situation."""

    def __init__(self, ds: MrclamDataset, start: float) -> None:
        self._ds, self._start = ds, float(start)

    def __getattr__(self, name: str):
        return getattr(self._ds, name)

    def time_span(self) -> tuple[float, float]:
        t0, t1 = self._ds.time_span()
        return t0 + self._start, t1

    def calibrated(self, calibration) -> LaterStart:
        """The calibrated dataset, starting as late (both runs read the calibrated copy)."""
        return LaterStart(self._ds.calibrated(calibration), self._start)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="mrslam experiment fusion_mrclam", description=__doc__)
    ap.add_argument("folder", help="MR.CLAM dataset folder, e.g. ../shared/data/mrclam/dataset6")
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--particles", type=int)
    ap.add_argument("--duration", type=float, help="seconds to process from the start")
    ap.add_argument("--merge-every", type=int, help="sets of an unmerged robot between alignment attempts")
    ap.add_argument("--pair-likelihood", action="store_true", help="weight joined pairs by their landmarks' agreement")
    ap.add_argument("--global-transform", action="store_true",
                    help="join every particle with the best maps' transform (no per-pair refit)")
    ap.add_argument("--filter", choices=["current", "pinned"], default="current",
                    help="MR.CLAM filter: current defaults, or the earlier pinned one (pinned_filter)")
    ap.add_argument("--no-rendezvous", action="store_true", help="merge by map alignment only")
    ap.add_argument("--join-uncertainty", choices=["drift", "proposal"],
                    help="where a map join puts the alignment's covariance (FusionConfig.transform_uncertainty)")
    ap.add_argument("--single-sighting", action="store_true",
                    help="join on one mutual sighting, without waiting for a second one that agrees")
    ap.add_argument("--rendezvous-anchor", action="store_true",
                    help="rendezvous joins anchored on each particle's own poses (FusionConfig.rendezvous_anchor)")
    ap.add_argument("--known", type=int, nargs="+", help="robots whose start pose is known (default 1)")
    ap.add_argument("--start", type=float, help="seconds of the log to skip (every robot starts there)")
    ap.add_argument("--out", default="runs/experiments")
    args = ap.parse_args(argv)
    ds = MrclamDataset(args.folder)
    if args.start:
        ds = LaterStart(ds, args.start)
    base = MrclamFusionConfig(rendezvous=not args.no_rendezvous)
    if args.filter == "pinned":
        base = replace(base, mrclam=replace(base.mrclam, filter=pinned_filter()))
    if args.global_transform:
        base = replace(base, fusion=replace(base.fusion, per_particle_alignment=False))
    if args.pair_likelihood:
        base = replace(base, fusion=replace(base.fusion, pair_likelihood=True))
    if args.join_uncertainty:
        base = replace(base, fusion=replace(base.fusion, transform_uncertainty=args.join_uncertainty))
    if args.rendezvous_anchor:
        base = replace(base, fusion=replace(base.fusion, rendezvous_anchor=True))
    if args.known:
        base = replace(base, known=tuple(args.known))
    if args.single_sighting:
        base = replace(base, fusion=replace(base.fusion, evidence_window=None))
    mc = base.mrclam
    if args.particles:
        mc = replace(mc, filter=replace(mc.filter, num_particles=args.particles))
    if args.duration:
        mc = replace(mc, duration=args.duration)
    if args.merge_every:
        mc = replace(mc, merge_every=args.merge_every)
    base = replace(base, mrclam=mc)
    runs = []
    for seed in range(args.seeds):
        cfg = replace(base, mrclam=replace(mc, filter=replace(mc.filter, seed=seed)))
        print(f"seed {seed}: robots {mc.robots}, known start {base.known}, M={mc.filter.num_particles}", flush=True)
        res = compare(ds, cfg, progress=True)
        runs.append(res)
        g = res["gauge"]["unknown_start"]
        print(f"  team frame offset (estimate -> Vicon, after merges): {np.hypot(g[0], g[1]):.3f} m, "
              f"{np.degrees(g[2]):.1f}°; known-start run: {np.degrees(res['gauge']['known_start'][2]):.1f}°", flush=True)
        for rname, r in res["robots"].items():
            m = res["merged"].get(rname)
            extra = "" if m is None else (f", merged at {m['time_s']:.0f} s by {m['via']} ({m['fused']} landmarks fused), "
                                          f"start error {m['start_error_m']:.3f} m {m['start_error_deg']:.2f}°")
            if "ate_m" in r:
                print(f"  {rname}: ATE after merge {r['ate_m']:.3f} m vs known start {r['ate_known_start_m']:.3f} m "
                      f"(ratio {r['ratio']:.2f}); team-aligned {r['gauge_free_ate_m']:.3f} vs "
                      f"{r['gauge_free_ate_known_start_m']:.3f} m{extra}", flush=True)
            else:
                print(f"  {rname}: never merged; last reason: {res['attempts'][rname][-1:]}", flush=True)
    names = list(runs[0]["robots"])
    lines = [
        (f"MR.CLAM {args.folder}, robots {list(base.known)} known start, others unknown; filter {args.filter}, "
         f"rendezvous {'on' if base.rendezvous else 'off'}; "
         f"M = {mc.filter.num_particles}, {args.seeds} seed(s); ATE RMSE [m] from the merge to the end, "
         "both runs over the same window. Unaligned = map frame as estimated (the bound applies to it); "
         "team-aligned = after ONE SE(2) transform fitted to all robots' post-merge positions jointly, per run"),
        "",
        "| seed | robot | merged at [s] by | fused landmarks | start-pose error [m] / [°] | unaligned ATE: unknown / known start | ratio | team-aligned ATE: unknown / known | ratio |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    worst = []
    for seed, res in enumerate(runs):
        g = res["gauge"]
        lines.append(f"| {seed} | team frame (fitted) | | | | rotation {np.degrees(g['unknown_start'][2]):.1f}° / "
                     f"{np.degrees(g['known_start'][2]):.1f}° | | | |")
        for rname in names:
            r, m = res["robots"][rname], res["merged"].get(rname)
            if m is None and "ate_m" not in r:
                lines.append(f"| {seed} | {rname} | never | | | – / {r['ate_known_start_full_m']:.3f} (full) | | | |")
                continue
            worst.append(r["ratio"])
            pair = (f"{r['ate_m']:.3f} / {r['ate_known_start_m']:.3f} | {r['ratio']:.2f} | "
                    f"{r['gauge_free_ate_m']:.3f} / {r['gauge_free_ate_known_start_m']:.3f} | {r['gauge_free_ratio']:.2f} |")
            if m is None:
                lines.append(f"| {seed} | {rname} | known start | | | {pair}")
            else:
                lines.append(f"| {seed} | {rname} | {m['time_s']:.0f} {m.get('via', '')} | {m['fused']} | "
                             f"{m['start_error_m']:.3f} / {m['start_error_deg']:.1f} | {pair}")
    lines += ["", (f"Unaligned ratio over all robots and seeds: max {max(worst):.2f}, median {np.median(worst):.2f}; "
                   f"{sum(w <= 1.5 for w in worst)} of {len(worst)} within 1.5.")]
    lines += ["", "Per robot over the seeds (one run is one draw of the filter: the median of each run's ATE "
              "estimates the robot's ATE):", "",
              "| robot | unaligned ATE, median over seeds: unknown / known start | ratio | ratio per seed: min / max |",
              "|---|---|---|---|"]
    for rname in names:
        rows = [res["robots"][rname] for res in runs if "ate_m" in res["robots"][rname]]
        if not rows:
            continue
        unk, kno = np.median([r["ate_m"] for r in rows]), np.median([r["ate_known_start_m"] for r in rows])
        ratios = [r["ratio"] for r in rows]
        lines.append(f"| {rname} | {unk:.3f} / {kno:.3f} | {unk / kno:.2f} | {min(ratios):.2f} / {max(ratios):.2f} |")
    text = "\n".join(lines)
    write_tables(args.out, "fusion_mrclam", text, {"runs": runs})
    return 0
