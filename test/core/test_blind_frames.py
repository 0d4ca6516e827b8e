"""``mrslam experiment blind_frames``: a run's frames re-rendered from its ground truth, counted by stage."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from mrslam_core.evaluation.tum import write_tum
from mrslam_core.experiments import blind_frames
from mrslam_core.frontend import FrontendConfig


@pytest.fixture
def small_run(tmp_path):
    """A run folder of two robots in the small room: robot1 turns on the spot at (3, 2) at 0.3 rad/s
    for 1 s; robot2 stands 1 m ahead of it (both ground truth at 10 Hz)."""
    team = {"robots": 2, "sim": {"world": "small", "texture_density": 64.0}}
    (tmp_path / "config.yaml").write_text(yaml.safe_dump({"team": team}))
    t = np.arange(0.0, 1.01, 0.1)
    (tmp_path / "trajectories").mkdir()
    write_tum(tmp_path / "trajectories/robot1_gt.tum", t, np.column_stack([np.full_like(t, 3.0), np.full_like(t, 2.0), 0.3 * t]))
    write_tum(tmp_path / "trajectories/robot2_gt.tum", t, np.tile([4.0, 2.0, np.pi], (len(t), 1)))
    return tmp_path


def test_frames_are_rendered_at_the_camera_rate_and_counted_by_stage(small_run):
    cfg = blind_frames.load_team(small_run)
    assert cfg.sim.world == "small" and cfg.frontend.min_track_length == 3  # the team's frontend
    rows = blind_frames.stage_counts(small_run, "robot1", 0.0, 1.0, cfg.frontend)
    assert [r["t"] for r in rows] == pytest.approx([0.0, 0.2, 0.4, 0.6, 0.8, 1.0])
    assert rows[3]["pose"] == pytest.approx([3.0, 2.0, 0.18])  # interpolated ground truth
    assert [r["published"] for r in rows[:2]] == [0, 0]  # tracks start at the first frame
    for r in rows:
        assert r["keypoints"] >= r["stereo"] >= r["in_depth"] >= r["tracked_2"] >= r["tracked_min"] >= r["published"]
    assert all(r["published"] >= 5 for r in rows[2:])  # a textured room, turning slowly


def test_frontend_changes_are_typed_and_checked():
    cfg = blind_frames.overrides(FrontendConfig(), ["harris_quality=0.001", "max_disparity=128"])
    assert cfg.harris_quality == 0.001 and cfg.max_disparity == 128
    with pytest.raises(SystemExit, match="FrontendConfig key"):
        blind_frames.overrides(cfg, ["no_such_key=1"])
