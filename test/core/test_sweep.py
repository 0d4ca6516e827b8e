"""`mrslam experiment sweep`: a tiny sweep writes its per-run JSON, table, numbers and plots, is
resumed from what it wrote, and a bad world ends in one line."""

import json

import numpy as np
import pytest

from mrslam_core.control.platform import PlatformConfig
from mrslam_core.evaluation.metrics import longest_stay
from mrslam_core.experiments.sweep import footprint_corners, longest_still, main


def test_a_tiny_sweep_writes_every_output_and_resumes(tmp_path, capsys):
    args = ["--worlds", "small", "--seeds", "0", "--robots", "1", "--seconds", "5", "--jobs", "1",
            "--out", str(tmp_path)]
    assert main(args) == 0
    run = tmp_path / "runs" / "small__seed0__robots1.json"
    record = json.loads(run.read_text())
    assert record["request"] == {"world": "small", "seed": 0, "robots": 1, "seconds": 5.0}
    robot = record["robots"]["robot1"]
    assert {"ate_rmse_m", "odom_ate_rmse_m", "ate_over_odom", "stuck_s", "stuck_from_s", "stuck_at",
            "still_s", "still_from_s", "still_at"} <= set(robot)
    assert 0 < robot["ate_rmse_m"] < 0.1 and 0 < robot["still_s"] <= robot["stuck_s"] <= 5.0
    folder = tmp_path / "runs" / record["folder"]  # as `mrslam team --out` writes it
    assert json.loads((folder / "report.json").read_text())["robots"]["robot1"]["ate_rmse_m"] == robot["ate_rmse_m"]
    assert (folder / "occupancy.yaml").is_file()
    coverage = np.array(record["coverage"])
    assert coverage[-1, 0] == record["seconds"] and 4.9 < record["seconds"] <= 5.0
    assert len(coverage) >= 6 and (np.diff(coverage[:, 1]) >= 0).all()  # every second, never less explored
    assert coverage[-1, 1] == record["explored_final"]
    assert 0 < record["reference"]["t90_s"] < 60  # perfect poses, 2-D: the small room in well under a minute
    assert record["t90_s"] == float("inf")  # not within 5 s
    assert {"p5", "p25", "p50", "p75", "p95", "max"} <= set(record["update_ms"])
    summary = json.loads((tmp_path / "sweep.json").read_text())
    assert summary["robot_runs"] == 1 and summary["runs"] == 1
    assert {"met_fraction", "median_ate_m", "exploration_failed", "stuck_max_s", "still_max_s", "still_over", "rows",
            "criteria"} <= set(summary)
    assert summary["exploration_failed"][0]["world"] == "small"
    assert "| small | small | 6 × 4 | 0 |" in (tmp_path / "sweep.md").read_text()
    for name in ("ate", "ratio", "explored", "stuck", "latency"):
        assert (tmp_path / f"sweep_{name}.png").stat().st_size > 5_000
    # resumed: the run is read back, not run again
    stamp = run.stat().st_mtime_ns
    assert main(args) == 0
    assert run.stat().st_mtime_ns == stamp


def test_a_bad_world_or_team_size_is_one_line_and_status_2(tmp_path, capsys):
    with pytest.raises(SystemExit) as done:
        main(["--help"])
    assert done.value.code == 0 and "--suite" in capsys.readouterr().out
    for argv, words in ((["--worlds", "castle"], "no world 'castle'"),
                        (["--worlds", "gen:office:1:scattered"], "start mode"),
                        (["--worlds", "small", "--robots", "5"],
                         "world small has 3 start poses, fewer than --robots 5")):
        assert main(argv + ["--out", str(tmp_path)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("mrslam experiment sweep: ") and words in err[0], err


def test_turning_on_the_spot_is_not_standing_still():
    """A robot at (1, 2) turns on the spot at 0.1 rad/s for 20 s, then stands 20 s (a pose every
    second). Its position never moves: it stayed 40 s. A point 1 m ahead of its axle moves
    2·sin(Δθ/2) m: more than 0.5 m once the heading turned more than 2·asin(0.25) = 0.505 rad
    from where the stretch began, so the longest still stretch begins at 15 s (heading 1.5 rad,
    0.5 rad short of the final 2.0) and lasts 25 s."""
    t = np.arange(41.0)
    poses = np.column_stack([np.ones(41), np.full(41, 2.0), 0.1 * np.minimum(t, 20.0)])
    assert longest_stay(t, poses, 0.5) == (40.0, 0)
    assert longest_still(t, poses, np.array([[1.0, 0.0]]), 0.5) == (25.0, 15)
    # driving back and forth 0.1 m without turning: still the whole time
    back_and_forth = poses.copy()
    back_and_forth[:, 0] += 0.1 * (t % 2)
    back_and_forth[:, 2] = 0.3
    assert longest_still(t, back_and_forth, np.array([[1.0, 0.0]]), 0.5) == (40.0, 0)


def test_the_footprint_corners_are_the_platforms():
    corners = footprint_corners(PlatformConfig(front=0.2, rear=0.3, width=0.4))
    np.testing.assert_array_equal(corners, [[0.2, 0.2], [0.2, -0.2], [-0.3, -0.2], [-0.3, 0.2]])
