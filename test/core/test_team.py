"""The closed loop in one process: simulator, frontends, one filter, grid, exploration. Its runs
are gated in test_world_gate.py (generated worlds, per-robot accuracy, determinism)."""

import numpy as np

from mrslam_core.pipelines.team import TeamConfig


def test_team_defaults_suit_the_5hz_stereo_frontend():
    # turning at max_turn_rate moves the image f·ω/rate px per frame; tracks must survive it
    cfg = TeamConfig()
    f = cfg.sim.camera.width / (2 * np.tan(np.radians(cfg.sim.camera.hfov_deg) / 2))
    per_frame = f * cfg.control.platform.max_turn_rate / cfg.sim.camera.rate_hz
    assert per_frame < cfg.frontend.track_radius_px
    platform = cfg.control.platform
    # planning keeps the body's corners clear, and a teammate's body is not mapped as a wall
    assert cfg.exploration.robot_radius >= platform.corner_radius
    assert cfg.grid.teammate_radius > platform.corner_radius
    # the platform's camera near limit is the simulated head's: the cameras' offset ahead of the
    # axle plus f·b / max_disparity (or min_depth, if farther), rounded up by at most 1 cm
    cam = cfg.sim.camera
    near = cam.mount_x + max(f * cam.baseline / cfg.frontend.max_disparity, cfg.frontend.min_depth)
    assert near <= platform.camera_near < near + 0.01
    assert cfg.control.turn_clearance >= platform.camera_near
    assert cfg.filter.association.descriptor_gate <= 0.25
    # the robots stand until a point tracked over min_track_length frames has been mapped, plus a frame
    assert cfg.exploration.start_delay >= (cfg.frontend.min_track_length + 1) / cfg.sim.camera.rate_hz
