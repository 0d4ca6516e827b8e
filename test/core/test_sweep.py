"""`mrslam experiment sweep`: a tiny sweep writes its per-run JSON, table, numbers and plots, is
resumed from what it wrote, and a bad world ends in one line."""

import json

import numpy as np
import pytest

from mrslam_core.experiments.sweep import main


def test_a_tiny_sweep_writes_every_output_and_resumes(tmp_path, capsys):
    args = ["--worlds", "small", "--seeds", "0", "--robots", "1", "--seconds", "5", "--jobs", "1",
            "--out", str(tmp_path)]
    assert main(args) == 0
    run = tmp_path / "runs" / "small__seed0__robots1.json"
    record = json.loads(run.read_text())
    assert record["request"] == {"world": "small", "seed": 0, "robots": 1, "seconds": 5.0}
    robot = record["robots"]["robot1"]
    assert {"ate_rmse_m", "odom_ate_rmse_m", "ate_over_odom", "stuck_s", "stuck_from_s", "stuck_at"} <= set(robot)
    assert 0 < robot["ate_rmse_m"] < 0.1 and 0 < robot["stuck_s"] <= 5.0
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
    assert {"met_fraction", "median_ate_m", "exploration_failed", "stuck_max_s", "rows", "criteria"} <= set(summary)
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
