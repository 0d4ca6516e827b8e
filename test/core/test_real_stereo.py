"""Real stereo imagery end to end: the frontend, its visual odometry and the dataset runner on the
KITTI odometry excerpt (51 frames, 60 m nearly straight) and the still EuRoC V1_01 pairs.

One profile (config/real_stereo.yaml), as a user runs it; the figures are in docs/results.md.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mrslam_core.configio import load_profile
from mrslam_core.datasets.stereo import open_sequence
from mrslam_core.experiments.stereo_frontend import evaluate
from mrslam_core.frontend.frontend import Frontend
from mrslam_core.pipelines.dataset import DatasetRunConfig, run
from mrslam_ros.dataset_cli import PROFILE

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def profile() -> DatasetRunConfig:
    return load_profile(DatasetRunConfig, PROFILE)


@pytest.fixture(scope="module")
def kitti(kitti_dir):
    return open_sequence("kitti", kitti_dir)


def test_the_frontend_publishes_b_consistent_points_on_kitti(kitti, profile):
    r = evaluate(kitti, profile.frontend)
    assert r["frames_with_B_points"] >= 0.90  # measured 0.96 (B = 20)
    assert r["pairs_within_gate"] >= 0.95  # measured 0.986, 3306 pairs
    assert 1.0 <= r["nees_median"] <= 3.5  # χ²(3) median 2.37; measured 1.88
    assert r["vo_endpoint_error_pct"] <= 1.0  # measured 0.90 % of 59.9 m
    assert abs(r["vo_heading_error_deg"]) <= 1.0  # measured +0.16°
    assert r["vo_failures"] == 0


@pytest.mark.parametrize("mode", ["orb", "sift"])
def test_orb_and_sift_modes_publish_about_as_many_points(kitti, profile, mode):
    r = evaluate(kitti, dataclasses.replace(profile.frontend, detector=mode, descriptor=mode))
    assert r["points_per_frame_mean"] >= 15  # measured 19.9 (ORB), 19.7 (SIFT)
    assert r["pairs_within_gate"] >= 0.95


def test_one_robot_on_visual_odometry_is_no_worse_than_the_visual_odometry(kitti, profile):
    res = run(kitti, profile)
    from mrslam_core.evaluation.report import robot_metrics

    m = robot_metrics(res["trajectories"]["robot1"])
    assert m["poses"] == 51
    assert m["ate_rmse_m"] <= m["odom_ate_rmse_m"]  # measured 0.23-0.29 m against 0.35 m, seeds 0-4
    assert res["robots"]["robot1"]["vo_endpoint_error_pct"] <= 1.0


@pytest.mark.parametrize("k", [2, 3])
def test_a_split_sequence_runs_as_k_robots_through_one_mapper(kitti, profile, k):
    res = run(kitti, dataclasses.replace(profile, split=k))
    from mrslam_core.evaluation.report import robot_metrics

    assert sorted(res["trajectories"]) == [f"robot{j + 1}" for j in range(k)]
    for name, tr in res["trajectories"].items():
        m = robot_metrics(tr)
        assert m["poses"] >= 51 // k
        assert m["ate_rmse_m"] <= 0.35  # measured 0.12-0.23 m (split 2), 0.04-0.22 m (split 3)
        assert m["ate_rmse_m"] <= 1.5 * m["odom_ate_rmse_m"]
    # each robot starts at its segment's ground truth in the whole sequence's map frame
    starts = np.array(list(res["start_poses"].values()))
    np.testing.assert_allclose(starts[0], 0.0, atol=1e-6)
    assert np.all(np.diff(starts[:, 0]) > 15)


def test_still_euroc_pairs_give_no_visual_odometry_drift(euroc_micro, profile):
    """The MAV stands (nearly) still for 30 frames (4.4 s). Drift: the frame-to-frame odometry's
    end pose against the motion measured directly between the first and the last frame."""
    seq = open_sequence("euroc", euroc_micro)
    fe = Frontend(seq.rig, profile.frontend)
    for i in range(len(seq)):
        fe.step(*seq.read(i), int(seq.frames[i].stamp_ns))
    assert fe.vo_failures == 0 and not fe.drops
    rect = seq.rig.t_base_rect
    chained = np.linalg.inv(rect) @ fe.odometry.pose @ rect  # the last camera in the first one
    direct = Frontend(seq.rig, profile.frontend)
    direct.step(*seq.read(0), 1)
    direct.step(*seq.read(len(seq) - 1), 2)
    drift = np.linalg.inv(direct.last_frame.motion.matrix()) @ chained

    def degrees(rot):
        return np.degrees(np.arccos(np.clip((np.trace(rot) - 1) / 2, -1, 1)))

    assert np.linalg.norm(drift[:3, 3]) <= 0.01  # measured 3.9 mm
    assert degrees(drift[:3, :3]) <= 0.2  # measured 0.09°
    # the MAV itself tilts by 0.17° (σ 0.06°) between frames 20 and 25, seen directly from frame
    # 0 to 25 and to 29 alike; the odometry ends 4.0 mm and 0.20° from its start
    assert degrees(direct.last_frame.motion.rotation) <= 0.3
    assert np.linalg.norm(chained[:3, 3]) <= 0.01 and degrees(chained[:3, :3]) <= 0.3
