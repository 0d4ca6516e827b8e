"""Every command turns a user's mistake (a missing or wrong path, a value out of range, a folder
that is not a bag, a bad option) into one line naming the problem and exit status 2, without a
traceback."""

import pytest

from mrslam_ros.cli import main

pytestmark = pytest.mark.ros


def _cases(tmp_path):
    bad_team = tmp_path / "team.yaml"
    bad_team.write_text("robots: 0\n")
    typo = tmp_path / "typo.yaml"
    typo.write_text("filter: {num_particle: 5}\n")
    return [
        (["mrclam", "/nonexistent"], "not a folder: /nonexistent"),
        (["mrclam", str(tmp_path), "--config", str(tmp_path / "none.yaml")], "cannot read"),
        (["mrclam", str(tmp_path), "--config", str(typo)], "num_particle"),
        (["mrclam", str(tmp_path), "--particles", "many"], "invalid int value"),
        (["team", "--robots", "0"], "must be at least 1"),
        (["team", "--config", str(bad_team)], "robots >= 1"),
        (["demo", "--robots", "0"], "must be at least 1"),
        (["replay", str(tmp_path), "--offline"], "not a rosbag2 folder"),
        (["replay", str(tmp_path / "nope")], "not a rosbag2 folder"),
        (["dataset", "run", "kitti", "/nonexistent", "--out", str(tmp_path / "o")], "/nonexistent"),
        (["launch", str(tmp_path / "none.yaml")], "none.yaml"),
        (["map", "load", str(tmp_path / "none.npz")], "none.npz"),
        (["bench", "filter", "--particles", "x"], "invalid int value"),
        (["experiment", "baseline_gtsam", "/nonexistent"], "/nonexistent"),
        (["nonsense"], "unknown command"),
    ]


def test_each_mistake_is_one_line_and_status_2(tmp_path, capsys):
    for argv, words in _cases(tmp_path):
        code = main(argv)
        err = capsys.readouterr().err
        lines = [line for line in err.splitlines() if line.strip()]
        assert code == 2, (argv, err)
        assert "Traceback" not in err, (argv, err)
        if argv[0] != "nonsense":  # the unknown command also lists the commands
            assert len(lines) == 1, (argv, err)
        assert lines[0].startswith("mrslam") and words in err, (argv, err)
