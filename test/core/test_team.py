"""The closed loop in one process: simulator, frontends, one filter, grid, exploration."""

from dataclasses import replace

import numpy as np
import pytest

from mrslam_core.evaluation.report import robot_metrics
from mrslam_core.pipelines.team import TeamConfig, run
from mrslam_core.sim.config import SimConfig


@pytest.mark.slow
def test_two_robots_map_and_explore_the_small_world():
    cfg = replace(TeamConfig(robots=2, seconds=15.0), sim=SimConfig(world="small"))
    res = run(cfg)
    assert res["explored_fraction"] > 0.3
    for name, tr in res["trajectories"].items():
        m = robot_metrics(tr)
        assert m["poses"] > 40  # 5 Hz stereo for 15 s
        assert m["ate_rmse_m"] < 0.3, (name, m)
        assert np.isfinite(tr["est"]).all()
    assert len(res["landmarks"]["mean"]) > 20
    assert sum(sum(d.values()) for d in res["frontend_drops"].values()) <= 4  # first frames only
