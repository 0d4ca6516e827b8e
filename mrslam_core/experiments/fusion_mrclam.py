"""``mrslam experiment fusion_mrclam DIR``: MR.CLAM with robots whose start pose is unknown (issue 8).

Robot 1 (the robots in ``known``) starts the central filter at its Vicon start pose; every other
robot runs its own filter (K = 1) from its own origin, knowing nothing of the others. A robot joins
the central filter particle by particle (004 section 5) either by a rendezvous — in a step in which
it and a robot of the central filter measure each other, which gives its pose in the common frame
directly (:mod:`mrslam_core.fusion.rendezvous`), once a second such sighting agrees — or, every ``try_every`` seconds, by aligning its
best map with the central best map (barcode descriptors, RANSAC, at least ``min_inliers``
inliers). From then on it is one more robot of the joint filter (its sightings of the other merged
robots and theirs of it are scored from then on).

Reported per merged robot: the merge time and how, the transform's error against the robot's true
start pose, and its ATE against Vicon from the merge to the end, next to the ATE of the known-start
run (:func:`mrslam_core.pipelines.mrclam.run` with the same config) over the SAME time window, both
unaligned and after one SE(2) transform fitted to the whole team.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, field, replace

import numpy as np

from mrslam_core.datasets.mrclam import MrclamDataset, OdometryIntegrator
from mrslam_core.evaluation.metrics import ate_rmse
from mrslam_core.experiments._output import write_tables
from mrslam_core.fusion.alignment import alignment_error, apply_transform, rigid_transform_2d
from mrslam_core.fusion.config import FusionConfig
from mrslam_core.fusion.gauge import hold_gauge
from mrslam_core.fusion.join import try_join
from mrslam_core.fusion.rendezvous import RendezvousGate, join_rendezvous, sighting_transform
from mrslam_core.pipelines.mrclam import MrclamConfig, _one_hot, measurement_frames
from mrslam_core.pipelines.mrclam import run as run_known_start
from mrslam_core.slam.config import FilterConfig
from mrslam_core.slam.filter import MultiRobotFastSLAM, RobotUpdate
from mrslam_core.types import ObservationSet, RobotSighting


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
        mrclam: the filter run, by default the MR.CLAM defaults (the known-start run it is
            compared with uses the same).
        fusion: alignment thresholds.
        known: robots whose start pose is known (they start the central filter).
        try_every: seconds between alignment attempts of each unmerged robot.
        hold_gauge: while the central map is empty, hold the known robots' poses at their
            weighted mean (:func:`mrslam_core.fusion.gauge.hold_gauge`), so the common frame is
            their dead reckoning rather than one random draw of its noise.
        rendezvous: also merge a robot once it and a robot of the central filter measure each
            other in the same step and a second such sighting within
            ``fusion.evidence_window`` agrees (:class:`~mrslam_core.fusion.rendezvous.RendezvousGate`),
            without waiting for the maps to overlap.
    """

    mrclam: MrclamConfig = field(default_factory=MrclamConfig)
    fusion: FusionConfig = field(default_factory=_mrclam_fusion)
    known: tuple[int, ...] = (1,)
    try_every: float = 5.0
    hold_gauge: bool = True
    rendezvous: bool = True


def run_unknown_start(ds: MrclamDataset, cfg: MrclamFusionConfig, progress: bool = False) -> dict:
    """Central filter for the known robots, local filters for the others, merged on alignment.

    Returns:
        {"times": (S+1,) [s], "est": {robot: (S+1, 3) map-frame estimate, NaN before merging},
         "gt": {robot: (S+1, 3)}, "merged": {robot: {"step", "time_s", "transform", "inliers",
         "rmse_m", "start_error_m", "start_error_deg", "fused", "added"}}, "attempts": {robot:
         [reasons]}, "update_ms": (S,)}
    """
    mc = cfg.mrclam
    robots = mc.numbers
    ds = ds.calibrated(mc.calibration)
    t0, t1 = ds.time_span()
    if mc.duration is not None:
        t1 = min(t1, t0 + mc.duration)
    nsteps = int(np.floor((t1 - t0) / mc.team_step))
    times = t0 + mc.team_step * np.arange(nsteps + 1)
    name = {i: f"robot{i}" for i in robots}
    starts = {i: ds.groundtruth(i, np.array([t0]))[0] for i in robots}
    odo = {i: OdometryIntegrator(ds.robots[i].odometry, mc.odometry_delay) for i in robots}
    lm_cov = np.diag([mc.sigma_range**2, mc.sigma_bearing**2])
    rr_cov = np.diag([mc.sigma_sighting_range**2, mc.sigma_sighting_bearing**2])

    per_step: dict[int, dict[int, np.ndarray]] = {}
    for i in robots:  # the known-start pipeline's frames, by window k: (t0 + (k−1)·period, t0 + k·period]
        frames = measurement_frames(ds, i, t0, times[-1])
        m = np.concatenate(frames) if frames else np.zeros((0, 4))
        k = np.maximum(np.ceil((m[:, 0] - t0) / mc.team_step - 1e-9), 1).astype(np.int64)
        splits = np.flatnonzero(np.diff(k)) + 1
        per_step[i] = {int(kk[0]): mm for kk, mm in zip(np.split(k, splits), np.split(m, splits)) if len(kk)}

    known = [i for i in robots if i in cfg.known]
    if not known:
        raise ValueError("at least one robot must have a known start pose")
    central = MultiRobotFastSLAM(mc.filter, [name[i] for i in known], np.array([starts[i] for i in known]))
    local = {
        i: MultiRobotFastSLAM(replace(mc.filter, seed=mc.filter.seed + i), [name[i]], np.zeros((1, 3)))
        for i in robots if i not in cfg.known
    }
    in_central = list(known)
    est = {name[i]: np.full((nsteps + 1, 3), np.nan) for i in robots}
    for i in known:
        est[name[i]][0] = starts[i]
    merged: dict[str, dict] = {}
    attempts: dict[str, list[str]] = {name[i]: [] for i in local}
    every = max(round(cfg.try_every / mc.team_step), 1)
    gate = RendezvousGate.from_config(cfg.fusion)  # one for sightings and alignments: they confirm each other

    def updates_for(i: int, k: int, group: list[int]) -> list[RobotUpdate]:
        m = per_step[i].get(k, np.zeros((0, 4)))
        out = []
        t_prev = times[k - 1]
        for t_meas in [*np.unique(m[:, 0]), None]:
            if t_meas is None:
                if t_prev >= times[k]:
                    break
                frame, tb = m[:0], times[k]
            else:
                frame, tb = m[m[:, 0] == t_meas], t_meas
            stamp = round((tb - t0) * 1e9)
            lm = frame[frame[:, 1] > ds.num_robots]
            obs = None
            if len(lm):
                obs = ObservationSet(name[i], stamp, lm[:, 2:4], np.broadcast_to(lm_cov, (len(lm), 2, 2)), _one_hot(lm[:, 1]))
            sightings = []
            if mc.use_sightings and len(group) > 1:
                for row in frame[frame[:, 1] <= ds.num_robots]:
                    if int(row[1]) in group and int(row[1]) != i:
                        sightings.append(RobotSighting(name[i], name[int(row[1])], row[2:4], rr_cov))
            out.append(RobotUpdate(name[i], stamp, odo[i].delta(t_prev, tb), obs, sightings))
            t_prev = tb
        return out

    def record(i: int, k: int, transform: np.ndarray, joined, via: str, inliers: int, matches: int, rmse: float) -> None:
        """Robot i joined the central filter at step k: log it and move it out of ``local``."""
        dt, dth = alignment_error(transform, starts[i])
        # the joined robot's pose: weighted mean against Vicon now, and the particles' own spread
        w = np.exp(central.log_w - np.logaddexp.reduce(central.log_w))
        p = central.poses[:, central.index[name[i]]]
        mean = central.estimate().mean[central.index[name[i]], :2]
        sd = float(np.sqrt(w @ ((p[:, :2] - mean) ** 2).sum(1)))
        truth = ds.groundtruth(i, times[k:k + 1])[0]
        merged[name[i]] = {
            "step": k, "time_s": float(times[k] - t0), "transform": np.asarray(transform).tolist(), "via": via,
            "inliers": inliers, "matches": matches, "rmse_m": rmse,
            "start_error_m": dt, "start_error_deg": float(np.degrees(dth)),
            "fused": joined.fused, "added": joined.added, "dropped": joined.dropped,
            "join_pose_error_m": float(np.linalg.norm(mean - truth[:2])), "join_pose_sd_m": sd,
            "local_ancestors": int(np.unique(joined.ancestors[:, 1]).size),
        }
        del local[i]
        in_central.append(i)
        if progress:
            print(f"  merged {name[i]} at {times[k] - t0:.1f} s by {via} ({inliers} inliers), "
                  f"start pose error {dt:.3f} m {np.degrees(dth):.2f}°; joined pose "
                  f"{merged[name[i]]['join_pose_error_m']:.3f} m off, particle spread {sd:.3f} m "
                  f"({merged[name[i]]['local_ancestors']} local ancestors)", file=sys.stderr, flush=True)

    step_ms = []
    report_every = max(nsteps // 10, 1)
    for k in range(1, nsteps + 1):
        tic = time.perf_counter()
        ups = [u for i in in_central for u in updates_for(i, k, in_central)]
        if cfg.hold_gauge:
            hold_gauge(central, [name[i] for i in known])
        central.step(ups)
        for i, slam in local.items():
            slam.step(updates_for(i, k, [i]))
        if cfg.rendezvous:
            for i in list(local):
                meet = mutual_sighting(per_step, k, i, in_central)
                if meet is None:
                    continue
                j, z_ij, z_ji = meet
                rv = gate.offer_sighting(name[i], float(times[k] - t0),
                                         sighting_transform(central, local[i], name[j], z_ij, z_ji, rr_cov, rr_cov))
                if rv is None:  # held until a second sighting agrees, or refused
                    attempts[name[i]].append(gate.log[name[i]][-1])
                    continue
                joined = join_rendezvous(central, local[i], name[i], rv, cfg.fusion)
                record(i, k, rv.transform, joined, f"rendezvous with {name[j]}", int(joined.fused), int(joined.fused), float("nan"))
        if k % every == 0:
            for i in list(local):
                al, joined = try_join(central, local[i], cfg.fusion, name[i], gate, float(times[k] - t0))
                if joined is None:
                    attempts[name[i]].append(f"{times[k] - t0:.1f} s: {al.reason}")
                    continue
                record(i, k, al.transform, joined, "map alignment", int(al.inliers.size), len(al.matches), al.rmse)
        step_ms.append((time.perf_counter() - tic) * 1e3)
        poses = central.estimate().mean
        for j, rname in enumerate(central.robots):
            est[rname][k] = poses[j]
        if progress and k % report_every == 0:
            print(f"  step {k}/{nsteps} ({100 * k // nsteps}%)", file=sys.stderr, flush=True)
    return {
        "times": times, "est": est, "gt": {name[i]: ds.groundtruth(i, times) for i in robots},
        "merged": merged, "attempts": attempts, "update_ms": np.array(step_ms),
    }


def mutual_sighting(
    per_step: dict[int, dict[int, np.ndarray]], k: int, i: int, group: list[int]
) -> tuple[int, np.ndarray, np.ndarray] | None:
    """A robot j of ``group`` that robot i measured in step k and that measured i in the same step:
    (j, i's last (range, bearing) of j, j's last of i), or None."""
    mine = per_step[i].get(k)
    if mine is None:
        return None
    for j in group:
        seen = mine[mine[:, 1] == j]
        if not len(seen):
            continue
        theirs = per_step[j].get(k)
        if theirs is None:
            continue
        back = theirs[theirs[:, 1] == i]
        if len(back):
            return j, seen[-1, 2:4].copy(), back[-1, 2:4].copy()
    return None


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
    known = run_known_start(ds, cfg.mrclam)
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
    ap.add_argument("--try-every", type=float, help="seconds between alignment attempts")
    ap.add_argument("--pair-likelihood", action="store_true", help="weight joined pairs by their landmarks' agreement")
    ap.add_argument("--global-transform", action="store_true",
                    help="join every particle with the best maps' transform (no per-pair refit)")
    ap.add_argument("--filter", choices=["current", "pinned"], default="current",
                    help="MR.CLAM filter: current defaults, or the earlier pinned one (pinned_filter)")
    ap.add_argument("--no-rendezvous", action="store_true", help="merge by map alignment only")
    ap.add_argument("--no-hold-gauge", action="store_true", help="sample the known robots' noise before the first landmark")
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
    base = MrclamFusionConfig(rendezvous=not args.no_rendezvous, hold_gauge=not args.no_hold_gauge)
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
    base = replace(base, mrclam=mc)
    if args.try_every:
        base = replace(base, try_every=args.try_every)
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
         f"rendezvous {'on' if base.rendezvous else 'off'}, hold gauge {'on' if base.hold_gauge else 'off'}; "
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
