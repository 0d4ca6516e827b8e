"""The GTSAM factor-graph baseline (issue 28): exact answers on a tiny synthetic team.

Frames: map x right, y up; a pose (x [m], y [m], θ [rad]) has x forward, y left; a bearing is
measured counter-clockwise from the robot's x axis, as in MR.CLAM.
"""

import numpy as np
import pytest

gtsam = pytest.importorskip("gtsam", reason="the GTSAM baseline needs the optional extra: pip install .[baselines]")

from mrslam_core.experiments.baseline_gtsam import (  # noqa: E402
    build_graph,
    nearest_pose,
    reexpress,
    solve_batch,
    solve_isam2,
)
from mrslam_core.geometry.se2 import between, compose  # noqa: E402

ROBOTS = (1, 2)
LANDMARKS = {6: np.array([2.0, 3.0]), 7: np.array([-1.0, 4.0])}
LM_COV = np.diag([0.02**2, 0.15**2])  # (bearing, range)
RR_COV = np.diag([0.04**2, 0.25**2])


def _truth() -> tuple[np.ndarray, np.ndarray]:
    """Two robots, 4 poses each, 1 s apart: robot 1 drives an arc, robot 2 drives straight."""
    times = np.arange(4.0)
    p1 = np.array([[0.0, 0.0, 0.0], [0.5, 0.1, 0.3], [0.9, 0.4, 0.6], [1.2, 0.8, 0.9]])
    p2 = np.array([[1.0, -1.0, np.pi / 2], [1.0, -0.6, np.pi / 2], [1.0, -0.2, np.pi / 2], [1.0, 0.2, np.pi / 2]])
    return times, np.stack([p1, p2])


def _measure(pose: np.ndarray, point: np.ndarray) -> tuple[float, float]:
    d = between(pose, np.array([point[0], point[1], 0.0]))
    return float(np.hypot(d[0], d[1])), float(np.arctan2(d[1], d[0]))


def _problem(outlier: float = 0.0) -> dict:
    times, poses = _truth()
    odometry = np.stack([between(p[:-1], p[1:]) for p in poses])
    cov = np.broadcast_to(np.diag([0.05**2, 0.05**2, 0.02**2]), (*odometry.shape[:2], 3, 3)).copy()
    rows = []
    for r, i in enumerate(ROBOTS):
        for k, t in enumerate(times):
            for s, lm in LANDMARKS.items():
                rows.append([i, t, s, *_measure(poses[r, k], lm)])
            other = 1 - r
            rows.append([i, t, ROBOTS[other], *_measure(poses[r, k], poses[other, k, :2])])
    meas = np.array(rows)
    meas[5, 3] += outlier  # robot 1 at t = 1 s: landmark 7's range
    return {
        "pose_times": times, "robot_ids": ROBOTS, "starts": poses[:, 0], "odometry": odometry,
        "odometry_cov": cov, "measurements": meas, "landmark_cov": LM_COV, "sighting_cov": RR_COV,
    }


def test_noiseless_team_is_recovered_exactly():
    _, truth = _truth()
    g = build_graph(**_problem())
    batch = solve_batch(g)
    assert batch["error"] < 1e-12  # the true poses satisfy every factor: conventions agree
    np.testing.assert_allclose(batch["poses"], truth, atol=1e-6)
    for s, p in LANDMARKS.items():
        np.testing.assert_allclose(batch["landmarks"][s], p, atol=1e-6)
    isam = solve_isam2(g)
    np.testing.assert_allclose(isam["poses"], truth, atol=1e-6)
    np.testing.assert_allclose(isam["online"], truth, atol=1e-6)
    np.testing.assert_allclose(solve_isam2(g, every=3)["poses"], truth, atol=1e-6)


def test_batch_corrects_a_wrong_odometry_step_from_the_measurements():
    # robot 2's odometry says it went 0.3 m too far in its second step, with σ = 0.3 m for that
    # step; three exact bearing-range measurements per pose pull it back to the truth
    _, truth = _truth()
    prob = _problem()
    prob["odometry"][1, 1, 0] += 0.3
    prob["odometry_cov"][1, 1] = np.diag([0.3**2, 0.3**2, 0.02**2])
    batch = solve_batch(build_graph(**prob))
    dead_reckoned = compose(truth[1, 1], prob["odometry"][1, 1])
    assert np.linalg.norm(dead_reckoned[:2] - truth[1, 2, :2]) == pytest.approx(0.3)
    err = np.linalg.norm(batch["poses"][1, 2:, :2] - truth[1, 2:, :2], axis=1)
    assert err.max() < 0.05


def test_a_robot_without_a_start_prior_is_placed_by_its_measurements():
    # robot 2's start is unknown: no prior, and its dead reckoning begins 0.4 m and 0.3 rad away
    # from the truth; its landmark and robot-1 readings put it exactly where it was
    _, truth = _truth()
    prob = _problem()
    prob["starts"] = prob["starts"].copy()
    prob["starts"][1] += [0.4, -0.3, 0.3]
    g = build_graph(**prob, known=np.array([True, False]))
    priors = [g.factors[0].at(i) for i in range(g.factors[0].size())]
    priors = [f.keys()[0] for f in priors if isinstance(f, gtsam.PriorFactorPose2)]
    assert priors == [g.pose_keys[0, 0]]
    batch = solve_batch(g)
    assert batch["error"] < 1e-12
    np.testing.assert_allclose(batch["poses"], truth, atol=1e-6)


def test_one_known_start_fixes_the_frame_and_nothing_else():
    # robot 1's first step is measured by odometry alone (nothing is read at pose 0), and the
    # odometry reports it as if the world were turned 0.05 rad about robot 1's start: with robot
    # 1's start the only prior, every other factor agrees with that turned world, and the
    # solution is the truth turned rigidly, robot 2 and the landmarks with it; with robot 2's
    # start known as well robot 2 stays where it was
    _, truth = _truth()
    prob = _problem()
    meas = prob["measurements"]
    prob["measurements"] = meas[meas[:, 1] > 0.0]
    turn = np.array([0.0, 0.0, -0.05])
    turned = compose(truth[0, 0], compose(turn, between(truth[0, 0], truth)))
    prob["odometry"][0, 0] = between(truth[0, 0], turned[0, 1])
    one = solve_batch(build_graph(**prob, known=np.array([True, False])))
    assert one["error"] < 1e-12
    np.testing.assert_allclose(one["poses"][:, 1:], turned[:, 1:], atol=1e-6)
    np.testing.assert_allclose(one["poses"][1, 0], turned[1, 0], atol=1e-6)
    both = solve_batch(build_graph(**prob))
    assert np.abs(both["poses"][1, 0] - truth[1, 0]).max() < 1e-3
    assert np.abs(both["poses"][1, 0] - turned[1, 0]).max() > 0.04


def test_huber_bounds_the_effect_of_an_outlier():
    _, truth = _truth()
    prob = _problem(outlier=3.0)
    robust = solve_batch(build_graph(**prob))
    gaussian = solve_batch(build_graph(**prob, huber_k=None))
    err_r = np.linalg.norm(robust["poses"][..., :2] - truth[..., :2], axis=-1).max()
    err_g = np.linalg.norm(gaussian["poses"][..., :2] - truth[..., :2], axis=-1).max()
    assert err_r < 0.02
    assert err_g > 2 * err_r


def test_measurement_reexpressed_at_the_nearest_pose_time():
    # a robot at pose A measures a point; after moving by delta it measures it again: the second
    # measurement re-expressed through delta is the first
    a = np.array([0.3, -0.2, 0.4])
    delta = np.array([0.05, 0.01, 0.03])
    point = np.array([2.0, 1.0])
    r, b = _measure(compose(a, delta), point)
    np.testing.assert_allclose(reexpress(np.array([[r, b]]), delta[None])[0], _measure(a, point), atol=1e-12)
    np.testing.assert_array_equal(nearest_pose(np.array([0.0, 0.2, 0.4]), np.array([0.05, 0.1, 0.11, 0.5])), [0, 0, 1, 2])


def test_missing_gtsam_is_one_line_and_exit_2(monkeypatch, capsys):
    import builtins

    from mrslam_core.experiments import baseline_gtsam

    real_import = builtins.__import__

    def no_gtsam(name, *args, **kwargs):
        if name == "gtsam":
            raise ImportError("no gtsam")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_gtsam)
    assert baseline_gtsam.main(["/nonexistent"]) == 2
    assert capsys.readouterr().out.strip() == (
        "mrslam experiment baseline_gtsam: gtsam is not installed (pip install .[baselines])"
    )
