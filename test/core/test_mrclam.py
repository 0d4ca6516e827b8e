"""MR.CLAM dataset 6: reader, dead reckoning, and the joint filter's accuracy against Vicon."""

from dataclasses import replace

import numpy as np
import pytest

from mrslam_core.datasets.mrclam import DatasetError, MrclamDataset, OdometryIntegrator
from mrslam_core.evaluation.report import robot_metrics
from mrslam_core.pipelines.mrclam import MrclamConfig, run


def test_arc_integration_is_exact():
    # v = 1 m/s, ω = π/2 rad/s for 1 s: a quarter circle of radius 2/π
    odo = np.array([[0.0, 1.0, np.pi / 2], [1.0, 0.0, 0.0]])
    integ = OdometryIntegrator(odo)
    r = 2 / np.pi
    np.testing.assert_allclose(integ.pose(1.0), [r, r, np.pi / 2], atol=1e-12)
    np.testing.assert_allclose(integ.delta(0.0, 1.0), [r, r, np.pi / 2], atol=1e-12)
    # a delay shifts the motion later
    late = OdometryIntegrator(odo, delay=0.5)
    np.testing.assert_allclose(late.pose(0.5), [0.0, 0.0, 0.0], atol=1e-12)


def test_missing_folder_is_a_clear_error(tmp_path):
    with pytest.raises(DatasetError, match="missing file"):
        MrclamDataset(tmp_path)


def test_reader_maps_barcodes_to_subjects(mrclam6):
    ds = MrclamDataset(mrclam6)
    assert ds.landmarks.shape == (15, 3)
    subjects = np.concatenate([r.measurements[:, 1] for r in ds.robots.values()])
    assert set(np.unique(subjects).astype(int)) <= set(range(1, 21))
    assert ds.unknown_barcodes == 6  # barcodes not in Barcodes.dat, dropped and counted
    t0, t1 = ds.time_span()
    assert 770 < t1 - t0 < 775


def test_short_run_writes_consistent_metrics(mrclam6):
    ds = MrclamDataset(mrclam6)
    cfg = MrclamConfig(duration=60.0)
    cfg = replace(cfg, filter=replace(cfg.filter, num_particles=100))
    res = run(ds, cfg)
    for tr in res["trajectories"].values():
        m = robot_metrics(tr)
        # 100 particles over 60 s: seed 0 gives 0.117 m at most (robot 5); over seeds 0-5 the
        # largest robot was 0.150 m, dead reckoning drifts metres over the run
        assert m["ate_rmse_m"] < 0.25
        np.testing.assert_allclose(tr["est"][0], tr["gt"][0], atol=1e-9)  # known start poses


@pytest.mark.slow
def test_joint_filter_accuracy_on_dataset6(mrclam6):
    """docs/results.md, MR.CLAM: the default config (through the central mapper), seed 0, all 772 s.

    Seed 0 gives 0.064 0.082 0.074 0.135 0.083 m (team mean 0.087 m); over seeds 0-19 robots 1,
    2, 3 and 5 stayed within 0.091 m, robot 4 within 0.151 m, and no team mean was above 0.099 m.
    Robot 4 (no landmark from 240 s to 340 s, dead reckoning in between) is the largest, at up
    to 19 % of its calibrated dead reckoning. The bounds are the top of that spread plus
    0.015-0.02 m (the filter is chaotic: a 1 µs change of the odometry delay moves a robot by
    several centimetres). The misread barcodes are dropped: the map holds the 15 landmarks. The
    five independent filters (0.45-0.49 m, 5x the joint filter's) are reported in docs/results.md,
    not run here: they doubled the test's CPU time for a comparison with that margin.
    """
    joint = run(MrclamDataset(mrclam6), MrclamConfig())
    ate = {n: robot_metrics(tr) for n, tr in joint["trajectories"].items()}
    for name, m in ate.items():
        assert m["ate_rmse_m"] <= (0.17 if name == "robot4" else 0.11), (name, m)
        assert m["ate_over_odom"] <= (0.25 if name == "robot4" else 0.12), (name, m)
    mean_joint = np.mean([m["ate_rmse_m"] for m in ate.values()])
    assert mean_joint <= 0.12
    assert len(joint["landmarks"]["mean"]) == 15
