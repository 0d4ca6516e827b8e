"""The simulator: kinematics, odometry noise, stereo geometry of the renderings, determinism,
collisions, worlds. Frames: map x, y on the floor; optical x right, y down, z forward."""

from dataclasses import replace

import cv2
import numpy as np
import pytest

from mrslam_core.sim.config import DriveConfig, OdometryNoiseConfig, SimConfig, StereoCameraConfig
from mrslam_core.sim.errors import SimError
from mrslam_core.sim.simulation import Simulation
from mrslam_core.sim.world import load_world

FAST = SimConfig(world="small", drive=DriveConfig(max_accel=1e6, max_turn_accel=1e6))


def test_unicycle_kinematics():
    with Simulation(FAST) as sim:
        sim.add_robot("r", np.array([1.0, 1.0, 0.3]))
        v, w, t = 0.4, 0.5, 2.0
        sim.set_command("r", v, w)
        sim.run_until(int(t * 1e9))
        th0 = 0.3
        want = [1.0 + v / w * (np.sin(th0 + w * t) - np.sin(th0)), 1.0 - v / w * (np.cos(th0 + w * t) - np.cos(th0)), th0 + w * t]
        np.testing.assert_allclose(sim.ground_truth("r"), want, atol=0.01)


def test_acceleration_limits():
    cfg = replace(FAST, drive=DriveConfig(max_accel=0.5))
    with Simulation(cfg) as sim:
        sim.add_robot("r", np.array([1.0, 2.0, 0.0]))
        sim.set_command("r", 0.5, 0.0)
        sim.run_until(int(0.5e9))  # v ramps 0 -> 0.25 m/s: distance 0.0625 m
        assert sim.ground_truth("r")[0] - 1.0 == pytest.approx(0.0625, abs=0.006)


def test_odometry_noise_statistics():
    k, dist = 1e-3, 2.0
    cfg = replace(FAST, odometry=OdometryNoiseConfig(scale_error_left=0, scale_error_right=0, track_error=0, k_wheel=k))
    ex, eth = [], []
    for seed in range(40):
        with Simulation(replace(cfg, seed=seed)) as sim:
            sim.add_robot("r", np.array([0.5, 2.0, 0.0]))
            sim.set_command("r", 0.5, 0.0)
            sim.run_until(int(dist / 0.5 * 1e9))
            odom, _ = sim.odometry("r")
            truth = sim.ground_truth("r")
            ex.append(odom[0] - (truth[0] - 0.5))
            eth.append(odom[2])
    # per wheel variance k·D; forward = mean of the wheels, heading = difference / track
    assert np.std(ex) == pytest.approx(np.sqrt(k * dist / 2), rel=0.35)
    assert np.std(eth) == pytest.approx(np.sqrt(2 * k * dist) / 0.33, rel=0.35)


def test_systematic_odometry_error():
    cfg = replace(FAST, odometry=OdometryNoiseConfig(scale_error_left=0.02, scale_error_right=0.02, track_error=0, k_wheel=0))
    with Simulation(cfg) as sim:
        sim.add_robot("r", np.array([0.5, 2.0, 0.0]))
        sim.set_command("r", 0.5, 0.0)
        sim.run_until(int(4e9))
        assert sim.odometry("r")[0][0] == pytest.approx(1.02 * (sim.ground_truth("r")[0] - 0.5), rel=1e-6)


def test_disparity_equals_fb_over_depth():
    cfg = replace(SimConfig(world="small"), camera=StereoCameraConfig(width=320, height=240))
    with Simulation(cfg) as sim:
        sim.add_robot("r", np.array([4.0, 2.0, 0.0]))  # facing the uniquely textured east wall
        frame = sim.render_stereo("r")
        left_cal, right_cal = sim.camera_calibrations()
        f, b = left_cal.P[0, 0], -right_cal.P[0, 3] / right_cal.P[0, 0]
        assert b == pytest.approx(0.12)
        sgbm = cv2.StereoSGBM_create(minDisparity=0, numDisparities=64, blockSize=7, uniquenessRatio=10)
        disp = sgbm.compute(frame.left, frame.right).astype(np.float32) / 16.0
        truth = f * b / frame.depth
        ok = (disp > 0) & (frame.depth < 10)
        assert ok.mean() > 0.3
        err = np.abs(disp[ok] - truth[ok])
        assert np.median(err) < 0.3 and np.mean(err < 1.0) > 0.9


def test_depth_of_a_wall_at_known_distance():
    with Simulation(SimConfig(world="small")) as sim:
        sim.add_robot("r", np.array([2.0, 2.0, np.pi]))
        frame = sim.render_stereo("r")
        # the wall's inner face is at x = 0.05; the camera is 0.12 m ahead of base_link
        h, w = frame.depth.shape
        assert frame.depth[h // 2, w // 2] == pytest.approx(2.0 - 0.12 - 0.05, abs=0.01)


def test_seeded_runs_are_identical():
    def run(seed):
        with Simulation(replace(SimConfig(world="small"), seed=seed)) as sim:
            sim.add_robot("r")
            sim.set_command("r", 0.3, 0.4)
            sim.run_until(int(1.5e9))
            return sim.odometry("r")[0], sim.render_stereo("r").left

    (o1, i1), (o2, i2), (o3, _) = run(3), run(3), run(4)
    np.testing.assert_array_equal(o1, o2)
    np.testing.assert_array_equal(i1, i2)
    assert not np.array_equal(o1, o3)


def test_robots_stop_at_walls():
    with Simulation(FAST) as sim:
        sim.add_robot("r", np.array([4.5, 2.5, 0.0]))
        sim.set_command("r", 0.6, 0.0)
        sim.run_until(int(6e9))  # 3.6 m of commands towards the east wall at x = 6 (face 5.95)
        x = sim.ground_truth("r")[0]
        assert 5.6 < x < 5.95 - 0.185 + 0.03  # body front is 0.185 m ahead of base_link


def test_world_files_and_occupancy(tmp_path):
    office = load_world("office")
    assert office.size == (20.0, 12.0) and len(office.start_poses) >= 3
    occ = office.occupancy(0.1)
    assert occ.shape == (120, 200)
    assert occ[60, 10] == False and occ[50, 10]  # noqa: E712 corridor free, y = 5 wall occupied
    bad = tmp_path / "w.yaml"
    bad.write_text("size: [4, 4]\nwalls: [[0, 0, 4]]\nstart_poses: [[1, 1, 0]]\n")
    with pytest.raises(SimError, match="walls must be a list of 4-number rows"):
        load_world(bad)
    bad.write_text("size: [4, 4]\nwals: []\n")
    with pytest.raises(SimError, match="unknown key wals"):
        load_world(bad)
    with pytest.raises(SimError, match="no world"):
        load_world("castle")


def test_bad_commands_and_names():
    with Simulation(SimConfig(world="small")) as sim:
        sim.add_robot("r")
        with pytest.raises(SimError, match="unknown robot"):
            sim.set_command("x", 0.1, 0.0)
        with pytest.raises(SimError, match="non-finite"):
            sim.set_command("r", np.nan, 0.0)
        with pytest.raises(SimError, match="exists already"):
            sim.add_robot("r")


def test_laser_scan_sees_the_wall():
    with Simulation(SimConfig(world="small")) as sim:
        sim.add_robot("r", np.array([2.0, 2.0, np.pi]))
        ranges = sim.laser_scan("r", num_beams=3, fov=0.2, max_range=5.0)
        assert ranges[1] == pytest.approx(2.0 - 0.05, abs=0.01)


def test_frontend_consumes_the_renderings():
    from mrslam_core.frontend.camera import StereoRig
    from mrslam_core.frontend.frontend import Frontend

    with Simulation(SimConfig(world="small")) as sim:
        sim.add_robot("r", np.array([3.0, 2.0, 0.0]))
        ext = sim.camera_extrinsic()
        left_cal, _ = sim.camera_calibrations()
        fe = Frontend(StereoRig(*sim.camera_calibrations(), ext), robot="r")
        sim.set_command("r", 0.1, 0.0)
        checked = 0
        for _ in range(5):
            sim.run_until(sim.time_ns + int(0.5e9))
            frame = sim.render_stereo("r")
            obs, _ = fe.step(frame.left, frame.right, frame.stamp_ns)
            if obs is None or not len(obs):
                continue
            # each observed point, moved back into the left optical frame, lies on the rendered surface
            opt = (obs.z - ext[:3, 3]) @ ext[:3, :3]
            uv = opt[:, :2] / opt[:, 2:] * left_cal.P[0, 0] + left_cal.P[:2, 2]
            u, v = np.round(uv).astype(int).T
            inside = (u >= 0) & (u < frame.depth.shape[1]) & (v >= 0) & (v < frame.depth.shape[0])
            depth = frame.depth[v[inside], u[inside]]
            rel = np.abs(opt[inside, 2] - depth) / depth
            assert np.median(rel) < 0.05  # 0.4 px of disparity at 2 m, 320 x 240
            checked += int(inside.sum())
        assert checked >= 10
