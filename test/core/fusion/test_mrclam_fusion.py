"""MR.CLAM dataset 6 with robots 2–5 given no start pose (docs/fusion.md): they are merged into
robot 1's central filter by a rendezvous (mutual sighting) or by map alignment, and then tracked in
the common (Vicon) frame about as well as when every start pose is known."""

from dataclasses import replace

import numpy as np
import pytest

from mrslam_core.datasets.mrclam import MrclamDataset, OdometryIntegrator
from mrslam_core.evaluation.metrics import ate_rmse
from mrslam_core.experiments.fusion_mrclam import MrclamFusionConfig, gauge_free, run_unknown_start
from mrslam_core.pipelines.mrclam import run as run_known_start


@pytest.mark.slow
def test_unknown_start_robots_are_merged_and_tracked(mrclam6):
    """First 300 s, M = 300, seed 0 (~25 s: the unknown-start run and the known-start run).
    Measured: robot 3's first mutual sighting with robot 1 (17.6 s) is held and the second
    (17.8 s) confirms it; robots 2 and 5 join by map alignment at 35 s, robot 4 at 75 s; ATE after
    the merge 0.29–0.32 m unaligned, 0.08–0.16 m team-aligned (the frame fitted away), against
    0.07–0.16 m and 0.07–0.13 m with every start pose known (team-aligned ratios 1.00–1.47);
    dead reckoning from the TRUE start pose over the same windows 0.57–1.13 m.
    The unaligned ratio to the known-start run (3.3 for robot 1) is not bounded here: the
    unknown-start run's frame rests on robot 1's start alone, the known-start run's on five
    (with the calibrated logs the latter fell to 0.07–0.16 m, the former's frame is 0.3 m off
    before any robot joins; docs/fusion.md)."""
    ds = MrclamDataset(mrclam6)
    cfg = MrclamFusionConfig()
    cfg = replace(cfg, mrclam=replace(cfg.mrclam, duration=300.0, filter=replace(cfg.mrclam.filter, num_particles=300)))
    res = run_unknown_start(ds, cfg)
    known = run_known_start(ds, cfg.mrclam)["trajectories"]
    merged = res["merged"]
    assert sorted(merged) == ["robot2", "robot3", "robot4", "robot5"], res["attempts"]
    assert merged["robot3"]["via"].startswith("rendezvous") and merged["robot3"]["time_s"] < 30
    # one mutual sighting is held, not trusted: robot 3 joins on the second that agrees
    assert any("held until a second piece of evidence" in a for a in res["attempts"]["robot3"]), res["attempts"]["robot3"]
    t0 = res["times"][0]
    first = {"robot1": 0, **{r: m["step"] for r, m in merged.items()}}
    free, _ = gauge_free(res["est"], res["gt"], first)
    free_known, _ = gauge_free({r: known[r]["est"] for r in res["gt"]}, res["gt"], first)
    raw, odo = {}, {}
    for r, k in first.items():
        if r != "robot1":
            m = merged[r]
            assert m["time_s"] <= 90
            if m["via"] == "map alignment":
                assert m["inliers"] >= 3 and m["rmse_m"] <= cfg.fusion.max_residual
            assert np.isnan(res["est"][r][:k]).all() and np.isfinite(res["est"][r][k:]).all()
        raw[r] = ate_rmse(res["est"][r][k:], res["gt"][r][k:])
        ref = ate_rmse(known[r]["est"][k:], res["gt"][r][k:])
        i = int(r[-1])
        dead = OdometryIntegrator(ds.robots[i].odometry, cfg.mrclam.odometry_delay).trajectory(
            ds.groundtruth(i, np.array([t0]))[0], res["times"])
        odo[r] = ate_rmse(dead[k:], res["gt"][r][k:])
        assert raw[r] < 0.4 and free[r] < 0.2, (r, raw[r], free[r], ref)
        # each robot's own error (the team frame removed in both runs) within 1.6x of the known start
        assert free[r] < 1.6 * free_known[r], (r, free[r], free_known[r])
    # far better than dead reckoning that even knows the true start pose
    assert np.mean(list(raw.values())) < 0.45 * np.mean(list(odo.values())), (raw, odo)
