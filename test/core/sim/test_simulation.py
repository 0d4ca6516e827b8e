"""The simulator: kinematics, collisions, odometry, stereo geometry of the renderings, determinism.

Frames: map x, y on the floor, z up; base_link x forward, y left; optical x right, y down, z forward.
The small world is a 6 × 4 m room whose walls are 0.1 m thick: inner faces at x = 0.05 and 5.95,
y = 0.05 and 3.95.
"""

from dataclasses import replace

import cv2
import numpy as np
import pytest

from mrslam_core.control.platform import PlatformConfig
from mrslam_core.sim import DriveConfig, OdometryNoiseConfig, SimConfig, SimError, Simulation, StereoCameraConfig

BODY = PlatformConfig()  # the simulated body's footprint
BODY_FRONT = BODY.front  # its front face ahead of base_link [m]

NO_NOISE = OdometryNoiseConfig(scale_error_left=0, scale_error_right=0, track_error=0, translation_var_per_m=0,
                               heading_var_per_m=0, heading_var_per_rad=0)
FAST = SimConfig(world="small", texture_density=32, drive=DriveConfig(max_accel=1e6, max_turn_accel=1e6),
                 odometry=NO_NOISE)


def test_unicycle_kinematics_and_exact_odometry():
    with Simulation(FAST) as sim:
        sim.add_robot("r", np.array([1.0, 1.0, 0.3]))
        v, w, t, th0 = 0.4, 0.5, 2.0, 0.3
        sim.set_command("r", v, w)
        sim.run_until(int(t * 1e9))
        want = [1.0 + v / w * (np.sin(th0 + w * t) - np.sin(th0)),
                1.0 - v / w * (np.cos(th0 + w * t) - np.cos(th0)), th0 + w * t]
        np.testing.assert_allclose(sim.ground_truth("r"), want, atol=0.005)
        np.testing.assert_allclose(sim.ground_truth_twist("r"), [v, w], atol=1e-3)
        # noiseless odometry is the true motion seen from the start pose
        odom, twist = sim.odometry("r")
        c, s = np.cos(th0), np.sin(th0)
        d = np.array(want[:2]) - [1.0, 1.0]
        np.testing.assert_allclose(odom, [c * d[0] + s * d[1], -s * d[0] + c * d[1], w * t], atol=0.005)
        np.testing.assert_allclose(twist, [v, w], atol=1e-3)


def test_speed_and_acceleration_limits():
    cfg = replace(FAST, drive=DriveConfig(max_accel=0.5, max_speed=0.3))
    with Simulation(cfg) as sim:
        sim.add_robot("r", np.array([1.0, 2.0, 0.0]))
        sim.set_command("r", 5.0, 0.0)  # clipped to 0.3 m/s, reached after 0.6 s
        sim.step(0.5)  # v ramps 0 -> 0.25 m/s: 0.0625 m
        assert sim.ground_truth("r")[0] - 1.0 == pytest.approx(0.0625, abs=0.006)
        sim.step(1.5)  # 0.5..0.6 s ramp to 0.3, then 1.4 s at 0.3: 0.0275 + 0.42 m
        assert sim.ground_truth("r")[0] - 1.0 == pytest.approx(0.0625 + 0.0275 + 0.42, abs=0.01)
        assert sim.ground_truth_twist("r")[0] == pytest.approx(0.3, abs=1e-3)


def test_robot_stops_at_a_wall_and_at_another_robot():
    with Simulation(FAST) as sim:
        sim.add_robot("r", np.array([4.5, 2.5, 0.0]))
        sim.set_command("r", 0.6, 0.0)
        sim.run_until(int(6e9))  # 3.6 m of commands towards the east wall (face at x = 5.95)
        x, y, th = sim.ground_truth("r")
        assert 5.95 - BODY_FRONT - 0.03 < x < 5.95 - BODY_FRONT + 0.01
        assert abs(y - 2.5) < 0.02 and abs(th) < 0.02
        # and another robot does not drive through it (rear of r's body is BODY.rear behind base_link)
        sim.add_robot("s", np.array([4.0, 2.5, 0.0]))
        sim.set_command("r", 0.0, 0.0)
        sim.set_command("s", 0.4, 0.0)
        sim.run_until(sim.time_ns + int(4e9))
        assert sim.ground_truth("s")[0] < sim.ground_truth("r")[0] - BODY.rear - BODY_FRONT + 0.03


def test_the_bumper_reports_where_the_body_touches_a_wall_in_base_link():
    """Driven head-on into the east wall (face at x = 5.95), the robot touches it with its front
    face, BODY.front ahead of base_link and within the body's width; standing free, it touches
    nothing (the floor is not a contact)."""
    with Simulation(FAST) as sim:
        sim.add_robot("r", np.array([4.5, 2.5, 0.0]))
        assert sim.contacts("r").shape == (0, 2)
        sim.set_command("r", 0.6, 0.0)
        sim.run_until(int(6e9))
        touch = sim.contacts("r")
        assert len(touch) >= 1
        np.testing.assert_allclose(touch[:, 0], BODY_FRONT, atol=0.015)
        assert np.all(np.abs(touch[:, 1]) <= BODY.width / 2 + 0.01)


def test_wheels_do_not_slip_sideways_against_a_wall():
    """Driving into the east wall at 50°, then turning on the spot against it: the robot stops
    instead of sliding along the wall, and whatever it does stays along its heading, so noiseless
    odometry equals the truth (a slide would be invisible to the wheels)."""
    with Simulation(FAST) as sim:
        sim.add_robot("r", np.array([5.0, 1.5, np.radians(50)]))
        sim.set_command("r", 0.4, 0.0)
        sim.run_until(int(5e9))  # 2 m of commands; the wall is ~1 m away along the heading
        stopped = sim.ground_truth("r")
        sim.run_until(int(8e9))
        np.testing.assert_allclose(sim.ground_truth("r"), stopped, atol=0.002)
        sim.set_command("r", 0.3, 0.8)  # keep pushing while turning towards the wall's normal
        sim.run_until(int(12e9))
        sim.set_command("r", -0.2, -0.5)
        sim.run_until(int(16e9))
        odom, _ = sim.odometry("r")
        from mrslam_core.geometry.se2 import compose
        np.testing.assert_allclose(compose(np.array([5.0, 1.5, np.radians(50)]), odom)[:2], sim.ground_truth("r")[:2], atol=0.01)
        assert sim.ground_truth("r")[0] < 5.95 - 0.1


def test_odometry_systematic_error():
    cfg = replace(FAST, odometry=replace(NO_NOISE, scale_error_left=0.02, scale_error_right=0.02))
    with Simulation(cfg) as sim:
        sim.add_robot("r", np.array([0.5, 2.0, 0.0]))
        sim.set_command("r", 0.5, 0.0)
        sim.run_until(int(4e9))
        assert sim.odometry("r")[0][0] == pytest.approx(1.02 * (sim.ground_truth("r")[0] - 0.5), rel=1e-6)
    cfg = replace(FAST, odometry=replace(NO_NOISE, track_error=0.05))
    with Simulation(cfg) as sim:
        sim.add_robot("r", np.array([3.0, 2.0, 0.0]))
        sim.set_command("r", 0.0, 1.0)  # on the spot: the odometry sees 1/1.05 of the turn
        sim.run_until(int(2e9))
        assert sim.odometry("r")[0][2] == pytest.approx(sim.ground_truth("r")[2] / 1.05, rel=1e-3)


def test_seeded_runs_are_identical_and_two_simulations_coexist():
    cfg = replace(SimConfig(world="small", texture_density=32), camera=StereoCameraConfig(width=64, height=48))

    def drive(sim):
        sim.add_robot("r")
        sim.set_command("r", 0.3, 0.4)
        sim.run_until(int(1.5e9))

    a, b, c = Simulation(cfg), Simulation(cfg), Simulation(replace(cfg, seed=4))
    with a, b, c:  # three clients alive at once
        for sim in (a, b, c):
            drive(sim)
        np.testing.assert_array_equal(a.odometry("r")[0], b.odometry("r")[0])
        np.testing.assert_array_equal(a.render_stereo("r").left, b.render_stereo("r").left)
        assert not np.array_equal(a.odometry("r")[0], c.odometry("r")[0])
        assert not np.array_equal(a.render_stereo("r").left, c.render_stereo("r").left)  # textures follow the seed


def test_render_schedule_follows_the_camera_rate():
    cfg = replace(FAST, camera=StereoCameraConfig(width=32, height=24, rate_hz=5.0))
    with Simulation(cfg) as sim:
        sim.add_robot("a")
        stamps = []
        while sim.time_ns < 2e9:
            for name in sim.step_until_frame():
                stamps.append(sim.render_stereo(name).stamp_ns)
        assert stamps == [int(k * 0.2e9) for k in range(11)]


def _slanted_view(width, height, encoding="mono8"):
    cfg = replace(SimConfig(world="small", texture_density=32),
                  camera=StereoCameraConfig(width=width, height=height, encoding=encoding))
    sim = Simulation(cfg)
    sim.add_robot("r", np.array([3.0, 2.0, 0.4]))  # sees the east wall (x = 5.95) slanted, and the floor
    return sim


@pytest.mark.parametrize("size", [(160, 120), (97, 61)])
def test_camera_info_matches_the_rendered_depth(size):
    """Back-project every pixel with K and the extrinsic; intersect with the wall plane x = 5.95
    and the floor z = 0; the rendered z-depth must agree (0.5 px of principal point error shows
    as 1e-3 relative here)."""
    with _slanted_view(*size) as sim:
        frame = sim.render_stereo("r")
        left, right = sim.camera_infos()
        k = left.K
        assert right.P[0, 3] == pytest.approx(-k[0, 0] * 0.12) and np.allclose(left.P[:, :3], k)
        x, y, th = sim.ground_truth("r")
        c, s = np.cos(th), np.sin(th)
        rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        ext = sim.camera_extrinsic("left")
        r_map, t_map = rot @ ext[:3, :3], np.array([x, y, 0]) + rot @ ext[:3, 3]
        u, v = np.meshgrid(np.arange(size[0]), np.arange(size[1]))
        rays = np.stack([(u - k[0, 2]) / k[0, 0], (v - k[1, 2]) / k[1, 1], np.ones(u.shape)], -1) @ r_map.T
        z_wall = (5.95 - t_map[0]) / rays[..., 0]
        with np.errstate(divide="ignore"):
            z_floor = np.where(rays[..., 2] < -0.02, -t_map[2] / rays[..., 2], np.inf)
        hit_wall = t_map + z_wall[..., None] * rays
        wall = (z_wall < z_floor) & (hit_wall[..., 2] > 0.02) & (hit_wall[..., 2] < 1.9) & (np.abs(hit_wall[..., 1] - 2) < 1.8)
        floor = (z_floor < z_wall) & (z_floor < 4)
        # pixels not showing the furniture (at x 3.5..4.5): depth within 5 cm of one of the planes
        for mask, z in ((wall, z_wall), (floor, z_floor)):
            ok = mask & (np.abs(frame.depth - z) < 0.05)
            assert ok.mean() > 0.1
            assert np.median(np.abs(frame.depth[ok] - z[ok]) / z[ok]) < 1e-4


@pytest.mark.parametrize("distance", [1.6, 2.0])
def test_disparity_is_fb_over_depth_subpixel(distance):
    """Facing the textured west wall squarely at a known distance: the rendered depth is the
    distance, and the left/right shift of the wall texture (phase correlation after removing the
    whole-pixel part, sub-pixel) equals f·b/Z. Texture sampling without filtering limits this to
    about ±0.2 px at the default texture density."""
    cfg = replace(SimConfig(world="small"), camera=StereoCameraConfig(width=320, height=240))
    with Simulation(cfg) as sim:
        sim.add_robot("r", np.array([distance, 2.0, np.pi]))
        frame = sim.render_stereo("r")
        left_cal, right_cal = sim.camera_infos()
        f, b = left_cal.P[0, 0], -right_cal.P[0, 3] / right_cal.P[0, 0]
        z = distance - 0.12 - 0.05  # camera 0.12 m ahead of base_link, wall face at x = 0.05
        rows, cols = slice(40, 120), slice(100, 228)  # wall only (the floor starts lower)
        np.testing.assert_allclose(frame.depth[rows, cols], z, atol=2e-3)
        whole = int(round(f * b / z))
        win = cv2.createHanningWindow((128, 80), cv2.CV_64F)
        right = frame.right[rows, cols.start - whole:cols.stop - whole].astype(np.float64)
        (shift, _), response = cv2.phaseCorrelate(right, frame.left[rows, cols].astype(np.float64), win)
        assert response > 0.5
        assert whole + shift == pytest.approx(f * b / z, abs=0.3)  # 15–20 px


def test_block_matching_on_the_rendered_pair_agrees_with_depth():
    with _slanted_view(320, 240) as sim:
        frame = sim.render_stereo("r")
        left_cal, right_cal = sim.camera_infos()
        fb = -right_cal.P[0, 3]
        sgbm = cv2.StereoSGBM_create(minDisparity=0, numDisparities=64, blockSize=7, uniquenessRatio=10)
        disp = sgbm.compute(frame.left, frame.right).astype(np.float32) / 16.0
        ok = (disp > 0) & (frame.depth < 8)
        assert ok.mean() > 0.5
        err = np.abs(disp[ok] - fb / frame.depth[ok])
        assert np.median(err) < 0.25 and np.mean(err < 1.0) > 0.9


def test_rgb_images():
    with _slanted_view(64, 48, "rgb8") as sim:
        frame = sim.render_stereo("r")
        assert frame.left.shape == (48, 64, 3) and frame.right.dtype == np.uint8 and frame.encoding == "rgb8"
        assert np.abs(frame.left[..., 0].astype(int) - frame.left[..., 2]).mean() > 5  # coloured, not grey


def test_laser_scan_sees_walls_and_robots():
    with Simulation(FAST) as sim:
        sim.add_robot("r", np.array([2.0, 2.0, np.pi]))
        ranges = sim.laser_scan("r", num_beams=3, fov=0.2, max_range=5.0)
        assert ranges[1] == pytest.approx(2.0 - 0.05, abs=1e-3)  # straight at the west wall
        assert ranges[0] == pytest.approx(1.95 / np.cos(0.1), abs=1e-3)
        sim.add_robot("s", np.array([1.0, 2.0, 0.0]))  # faces r; s's body front is 0.185 m ahead
        assert sim.laser_scan("r", num_beams=1, fov=0.01)[0] == pytest.approx(1.0 - BODY_FRONT, abs=1e-3)
        assert sim.laser_scan("r", num_beams=1, fov=0.01, max_range=0.5)[0] == 0.5


def test_a_placed_robot_is_there_at_rest_and_its_odometry_did_not_move():
    with Simulation(FAST) as sim:
        sim.add_robot("r", np.array([1.0, 1.0, 0.0]))
        sim.set_command("r", 0.3, 0.0)
        sim.step()
        odom = sim.odometry("r")[0]
        sim.place("r", np.array([2.0, 2.0, np.pi]))
        assert sim.ground_truth("r") == pytest.approx([2.0, 2.0, np.pi])
        assert sim.laser_scan("r", num_beams=1, fov=0.01)[0] == pytest.approx(2.0 - 0.05, abs=1e-3)  # the west wall
        sim.set_command("r", 0.0, 0.0)
        sim.step()
        assert sim.ground_truth("r") == pytest.approx([2.0, 2.0, np.pi])
        assert sim.odometry("r")[0] == pytest.approx(odom)
        with pytest.raises(SimError, match="3 finite numbers"):
            sim.place("r", np.array([np.nan, 0.0, 0.0]))


def test_bad_input():
    with Simulation(FAST) as sim:
        sim.add_robot("r")
        with pytest.raises(SimError, match="unknown robot"):
            sim.set_command("x", 0.1, 0.0)
        with pytest.raises(SimError, match="non-finite"):
            sim.set_command("r", np.nan, 0.0)
        with pytest.raises(SimError, match="exists already"):
            sim.add_robot("r")
        with pytest.raises(SimError, match="3 finite numbers"):
            sim.add_robot("q", np.array([1.0, 2.0]))
    with pytest.raises(SimError, match="rate_hz"):
        StereoCameraConfig(rate_hz=0)
    with pytest.raises(SimError, match="no robots"):
        with Simulation(FAST) as sim:
            sim.step_until_frame()


@pytest.mark.parametrize("v", [0.3, -0.3])
def test_a_side_touching_a_wall_slides_along_it(v):
    """Heading north with its right side against the west wall (face at x = 0.05), the robot
    drives along the wall both ways at full speed: a contact normal perpendicular to the heading
    does not block the wheels, whatever the sign of cos(π/2)'s rounding in the dot product."""
    with Simulation(FAST) as sim:
        sim.add_robot("r", np.array([0.05 + BODY.width / 2 - 0.002, 2.0, np.pi / 2]))
        sim.step()
        assert len(sim.contacts("r")) >= 1
        sim.set_command("r", v, 0.0)
        sim.run_until(sim.time_ns + int(1e9))  # 0.3 m, short of the small world's box at y = 1.3
        x, y, th = sim.ground_truth("r")
        assert y - 2.0 == pytest.approx(v, abs=0.01)
        assert abs(th - np.pi / 2) < 1e-3 and abs(x - (0.05 + BODY.width / 2)) < 0.01
