"""``mrslam dataset run``: the run folder a user gets, and one-line answers to their mistakes."""

from __future__ import annotations

import json

import pytest

from mrslam_ros.cli import main


def test_a_short_kitti_run_writes_the_run_folder(kitti_dir, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["dataset", "run", "kitti", str(kitti_dir), "--out", str(out), "--frames", "12", "--quiet"]) == 0
    report = json.loads((out / "report.json").read_text())
    r = report["robots"]["robot1"]
    assert r["poses"] == 12 and r["ate_rmse_m"] < 0.2  # 13 m driven
    assert report["frontend"]["robot1"]["frames"] == 12 and report["frontend"]["robot1"]["vo_failures"] == 0
    assert report["config"]["frontend"]["max_features"] == 800  # the real stereo profile
    for name in ("robot1_est.tum", "robot1_gt.tum", "robot1_odom.tum"):
        assert len((out / "trajectories" / name).read_text().splitlines()) == 12
    assert (out / "config.yaml").is_file() and (out / "trajectories.png").is_file()
    assert "visual odometry end point" in capsys.readouterr().out


@pytest.mark.parametrize("args, says", [
    (["run", "kitti", "/nonexistent/seq", "--out", "X"], "/nonexistent/seq"),
    (["run", "tum", ".", "--out", "X"], "tum"),
    (["run", "kitti", "KITTI", "--out", "X", "--split", "0"], "split"),
    (["run", "kitti", "KITTI", "--out", "X", "--config", "/nonexistent.yaml"], "/nonexistent.yaml"),
    (["run", "kitti"], "required"),
    (["frobnicate"], "expected 'import' or 'run'"),
])
def test_mistakes_get_one_line_and_status_2(kitti_dir, tmp_path, capsys, args, says):
    args = [str(kitti_dir) if a == "KITTI" else str(tmp_path / "out") if a == "X" else a for a in args]
    assert main(["dataset", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0], err


def test_a_corrupt_frame_is_counted_and_the_run_goes_on(kitti_dir, tmp_path, capsys):
    import shutil

    seq = tmp_path / "seq"
    for side in ("image_l", "image_r"):
        (seq / side).mkdir(parents=True)
        for i in range(10):
            shutil.copy(kitti_dir / side / f"{i:06d}.png", seq / side / f"{i:06d}.png")
    shutil.copy(kitti_dir / "calib.txt", seq / "calib.txt")
    (seq / "poses.txt").write_text("".join((kitti_dir / "poses.txt").read_text().splitlines(True)[:10]))
    (seq / "image_l" / "000006.png").write_bytes(b"\x89PNG\r\n\x1a\n truncated")
    out = tmp_path / "run"
    assert main(["dataset", "run", "kitti", str(seq), "--out", str(out), "--quiet"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["frontend"]["robot1"]["unusable_frames"] == 1
    assert report["robots"]["robot1"]["poses"] == 9
