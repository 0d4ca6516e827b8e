"""mrslam map export/load: the best particle's map survives every file format exactly (npz, csv)
or to the stored precision (ply), from a checkpoint or a run folder."""

import numpy as np
import pytest

from mrslam_core.datasets.synthetic import SyntheticWorld, SyntheticWorldConfig
from mrslam_core.mapio import MapFileError, load_map, main, map_from_checkpoint, save_map
from mrslam_core.slam.checkpoint import save_checkpoint
from mrslam_core.slam.config import FilterConfig
from mrslam_core.slam.filter import MultiRobotFastSLAM, RobotUpdate
from mrslam_core.types import ObservationSet


@pytest.fixture(scope="module")
def stereo_slam():
    world = SyntheticWorld(SyntheticWorldConfig(seed=4, num_robots=2, descriptor_dim=8))
    slam = MultiRobotFastSLAM(FilterConfig(num_particles=12, seed=1), world.robots, world.start_poses())
    for _, _, _, ups in world.run(6):
        slam.step(ups)
    return slam


def _planar_slam():
    cfg = FilterConfig(num_particles=5, seed=2, observation_model="range_bearing")
    slam = MultiRobotFastSLAM(cfg, ["a"], np.zeros((1, 3)))
    z = np.array([[2.0, 0.3], [3.0, -0.4], [1.5, 1.0]])
    obs = ObservationSet("a", 1, z, np.broadcast_to(np.diag([0.01, 0.001]), (3, 2, 2)), np.eye(3, 4, dtype=np.float32))
    slam.step([RobotUpdate("a", 1, np.zeros(3), obs)])
    return slam


@pytest.mark.parametrize("planar", [False, True])
def test_export_and_load_round_trip(tmp_path, stereo_slam, planar):
    slam = _planar_slam() if planar else stereo_slam
    ckpt = save_checkpoint(slam, tmp_path / "run" / "checkpoints" / "filter.ckpt")
    (tmp_path / "run" / "report.json").write_text("{}")  # other files of a run are skipped
    np.savez(tmp_path / "run" / "other.npz", a=np.zeros(2))
    slots, mean, cov, desc, count = slam.best_map()
    assert slots.size > 0
    lmap = map_from_checkpoint(tmp_path / "run")  # a run folder: its newest checkpoint
    assert lmap.meta["source"] == str(ckpt) and lmap.dim == (2 if planar else 3)
    for suffix, exact in ((".npz", True), (".csv", True), (".ply", False)):
        out = save_map(lmap, tmp_path / f"map{suffix}")
        back = load_map(out)
        np.testing.assert_array_equal(back.slots, slots)
        np.testing.assert_array_equal(back.count, count)
        np.testing.assert_array_equal(back.descriptor, desc)
        # the filter keeps float32 landmarks: every format holds them exactly as float64
        np.testing.assert_array_equal(back.mean, mean.astype(float))
        np.testing.assert_array_equal(back.cov, cov.astype(float)) if exact else np.testing.assert_allclose(back.cov, cov, rtol=1e-7)
    # a checkpoint is also readable directly as a map
    np.testing.assert_array_equal(load_map(ckpt).mean, mean.astype(float))


def test_ply_is_standard(tmp_path, stereo_slam):
    lmap = map_from_checkpoint(save_checkpoint(stereo_slam, tmp_path / "c.npz"))
    out = save_map(lmap, tmp_path / "m.ply")
    head = out.read_bytes().split(b"end_header\n")[0].decode()
    assert head.startswith("ply\nformat binary_little_endian 1.0\n")
    assert f"element vertex {len(lmap)}" in head
    assert "property double x\nproperty double y\nproperty double z" in head
    assert len(out.read_bytes()) == len(head) + len("end_header\n") + len(lmap) * (3 * 8 + 2 * 4 + 6 * 8 + 8 * 4)


def test_cli_export_and_load(tmp_path, stereo_slam, capsys):
    save_checkpoint(stereo_slam, tmp_path / "run" / "filter.npz")
    assert main(["export", str(tmp_path / "run"), "--out", str(tmp_path / "map.csv")]) == 0
    assert main(["load", str(tmp_path / "map.csv")]) == 0
    text = capsys.readouterr().out
    n = stereo_slam.best_map()[0].size
    assert f"{n} landmarks (dim 3, descriptor length 8)" in text
    assert "extent [m]" in text and "robot1" in text


def test_bad_inputs(tmp_path, stereo_slam, capsys):
    (tmp_path / "empty").mkdir()
    with pytest.raises(MapFileError, match="no filter checkpoint"):
        map_from_checkpoint(tmp_path / "empty")
    lmap = map_from_checkpoint(save_checkpoint(stereo_slam, tmp_path / "c.npz"))
    with pytest.raises(MapFileError, match="format"):
        save_map(lmap, tmp_path / "map.txt")
    (tmp_path / "x.csv").write_text("a,b\n1,2\n")
    (tmp_path / "x.ply").write_bytes(b"ply\nformat ascii 1.0\nend_header\n")
    (tmp_path / "x.npz").write_bytes(b"junk")
    for name in ("x.csv", "x.ply", "x.npz", "missing.npz"):
        with pytest.raises(MapFileError):
            load_map(tmp_path / name)
    truncated = tmp_path / "t.ply"
    truncated.write_bytes(save_map(lmap, tmp_path / "m.ply").read_bytes()[:-10])
    with pytest.raises(MapFileError, match="vertices need"):
        load_map(truncated)
    assert main(["load", str(tmp_path / "x.npz")]) == 2
    assert "mrslam map:" in capsys.readouterr().err
