"""Filter checkpoints: a reloaded filter continues bit for bit like the original, the file loads
without pickle, the write is atomic, and bad files give CheckpointError."""

from dataclasses import replace

import numpy as np
import pytest

from mrslam_core.datasets.synthetic import SyntheticWorld, SyntheticWorldConfig
from mrslam_core.slam.checkpoint import (
    FILTER_ATTRIBUTES,
    STORE_ATTRIBUTES,
    CheckpointError,
    load_checkpoint,
    read_header,
    save_checkpoint,
)
from mrslam_core.slam.config import ExistenceConfig, FilterConfig
from mrslam_core.slam.filter import MultiRobotFastSLAM, RobotUpdate
from mrslam_core.types import RobotSighting

WORLD = SyntheticWorldConfig(seed=11, num_robots=2, sigma_d=1.0, sigma_r=10.0, sigma_c=10.0)


def assert_same_state(a: MultiRobotFastSLAM, b: MultiRobotFastSLAM) -> None:
    for name in ("poses", "log_w", "score"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    sa, sb = a.landmarks, b.landmarks
    assert sa.check() == [] and sb.check() == []
    for name in ("descriptor", "ref", "origin", "born", "maker"):
        np.testing.assert_array_equal(getattr(sa, name), getattr(sb, name), err_msg=name)
    # every particle's values at every slot (which pool chunk or node holds them is the store's
    # business: a reloaded store recycles free ids in another order)
    m, slots = np.arange(sa.num_particles)[:, None], np.arange(sa.size)[None]
    fields = ("mean", "cov", "exists", "count", "score")
    for name, x, y in zip(fields, sa.gather(m, slots, fields), sb.gather(m, slots, fields)):
        np.testing.assert_array_equal(x, y, err_msg=name)
    assert a.landmarks.size == b.landmarks.size
    assert (a.last_stamp, a.dropped) == (b.last_stamp, b.dropped)
    assert a.rng.bit_generator.state == b.rng.bit_generator.state
    # every other attribute (counters, flags, per-robot arrays) is restored with its value
    assert set(vars(a)) == set(vars(b))
    for name in set(vars(a)) - FILTER_ATTRIBUTES:
        va, vb = getattr(a, name), getattr(b, name)
        if isinstance(va, dict):
            assert sorted(va) == sorted(vb), name
            for k in va:
                np.testing.assert_array_equal(va[k], vb[k], err_msg=f"{name}[{k}]")
        else:
            np.testing.assert_array_equal(va, vb, err_msg=name)
            assert type(va) is type(vb), name
    for x, y in zip(a.best_map(), b.best_map()):
        np.testing.assert_array_equal(x, y)


def _with_sightings(updates, step):
    # every 3rd step robot1 measures robot2 (range-bearing), to exercise that path too
    if step % 3:
        return updates
    s = RobotSighting("robot1", "robot2", np.array([3.0, 0.2]), np.diag([0.05, 0.01]))
    return [replace(updates[0], sightings=[s])] + list(updates[1:])


@pytest.mark.parametrize("proposal", ["fastslam1", "fastslam2", "fastslam2+relocalization", "fastslam2+tracks"])
def test_reloaded_filter_continues_bit_for_bit(tmp_path, proposal):
    cfg = FilterConfig(
        num_particles=25, seed=3, proposal=proposal.split("+")[0], resample_threshold=0.9,
        initial_pose_sigma=(0.02, 0.02, 0.01), sighting_outlier_probability=0.05,
        existence=ExistenceConfig(enabled=True, max_range=6.0),
    )
    if proposal.endswith("relocalization"):  # per-robot drift covariances in the state
        config = pytest.importorskip("mrslam_core.slam.config")
        if not hasattr(config, "RelocalizationConfig"):
            pytest.skip("this filter has no relocalization")
        cfg = replace(cfg, relocalization=config.RelocalizationConfig(enabled=True))
    if proposal.endswith("tracks"):  # per-robot track memories (the synthetic sets carry track ids)
        cfg = replace(cfg, association=replace(cfg.association, track_gate=30.0))
    world = SyntheticWorld(WORLD)
    data = [_with_sightings(ups, i) for i, (_, _, _, ups) in enumerate(world.run(24))]
    slam = MultiRobotFastSLAM(cfg, world.robots, world.start_poses())
    for ups in data[:12]:
        slam.step(ups)
    slam.step([RobotUpdate("ghost", 1, np.zeros(3))])  # a drop counter to carry over
    slam.landmarks.compact()  # a renumbered pool with free chunks, as after a long run
    assert slam.resamples > 0 and slam.landmarks.size > 0
    path = save_checkpoint(slam, tmp_path / "filter.ckpt", {"wall_s": 12.5, "odom": np.arange(6.0).reshape(2, 3)})
    copy, extra = load_checkpoint(path)
    assert extra["wall_s"] == 12.5
    np.testing.assert_array_equal(extra["odom"], np.arange(6.0).reshape(2, 3))
    assert copy.config == cfg and copy.robots == slam.robots
    assert_same_state(slam, copy)
    assert set(slam.tracks) == ({0, 1} if proposal.endswith("tracks") else set())
    for k, memory in slam.tracks.items():
        assert memory.ids.size > 0 and memory.sets == copy.tracks[k].sets
        for name in ("ids", "slots", "last"):
            np.testing.assert_array_equal(getattr(memory, name), getattr(copy.tracks[k], name))
    for ups in data[12:]:
        ra, rb = slam.step(ups), copy.step(ups)
        assert ra == rb
    assert slam.resamples > 0
    assert_same_state(slam, copy)
    np.testing.assert_array_equal(slam.estimate().mean, copy.estimate().mean)


def test_range_bearing_filter_round_trips(tmp_path):
    cfg = FilterConfig(num_particles=10, seed=1, observation_model="range_bearing")
    slam = MultiRobotFastSLAM(cfg, ["a", "b"], np.array([[0.0, 0, 0], [2.0, 0, 0]]))
    cov = np.diag([0.01, 0.001])
    for t in range(1, 4):
        slam.step([RobotUpdate("a", t, np.array([0.1, 0, 0]), sightings=[RobotSighting("a", "b", np.array([2.0, 0.0]), cov)])])
    copy, extra = load_checkpoint(save_checkpoint(slam, tmp_path / "rb.npz", {}))
    assert extra == {} and copy.model.name == "range_bearing"
    upd = [RobotUpdate("b", 5, np.array([0.2, 0.0, 0.1]))]
    slam.step(upd)
    copy.step(upd)
    assert_same_state(slam, copy)


def test_checkpoint_knows_every_piece_of_filter_state(tmp_path):
    # if the store grows new attributes, the checkpoint must learn to save them; the filter's
    # other attributes are saved by type, and one of a type with no form stops the save
    slam = MultiRobotFastSLAM(FilterConfig(num_particles=3), ["a"], np.zeros((1, 3)))
    assert set(vars(slam.landmarks)) <= STORE_ATTRIBUTES, set(vars(slam.landmarks)) - STORE_ATTRIBUTES
    slam.some_counter, slam.some_flag, slam.per_robot = np.int64(4), False, {0: np.eye(2)}
    copy, _ = load_checkpoint(save_checkpoint(slam, tmp_path / "a.npz"))
    assert not hasattr(copy, "some_counter")  # unknown to a fresh filter: not restored
    slam.odd = [object()]
    with pytest.raises(CheckpointError, match="odd"):
        save_checkpoint(slam, tmp_path / "b.npz")
    assert not (tmp_path / "b.npz").exists()


def test_file_is_plain_npz_and_write_is_atomic(tmp_path):
    slam = MultiRobotFastSLAM(FilterConfig(num_particles=4, seed=2), ["a"], np.zeros((1, 3)))
    path = tmp_path / "c.npz"
    save_checkpoint(slam, path, {"note": "first"})
    with np.load(path, allow_pickle=False) as data:  # no object arrays anywhere
        assert all(data[name].dtype != object for name in data.files)
        assert data["filter.poses"].shape == (4, 1, 3)
    header = read_header(path)
    assert header["version"] == 3 and header["robots"] == ["a"] and header["extra"] == {"note": "first"}
    assert header["config"]["num_particles"] == 4
    # an extra value that would need pickle: error, and the previous checkpoint is intact
    with pytest.raises(CheckpointError):
        save_checkpoint(slam, path, {"bad": object()})
    with pytest.raises(CheckpointError):
        save_checkpoint(slam, path, {"bad": np.array(["x"], object)})
    assert read_header(path)["extra"] == {"note": "first"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.npz"]  # no temp files left


def test_bad_files_give_checkpoint_error(tmp_path):
    slam = MultiRobotFastSLAM(FilterConfig(num_particles=4), ["a"], np.zeros((1, 3)))
    good = save_checkpoint(slam, tmp_path / "good.npz")
    (tmp_path / "text.npz").write_text("not a zip")
    with pytest.raises(CheckpointError):
        load_checkpoint(tmp_path / "text.npz")
    with pytest.raises(CheckpointError):
        load_checkpoint(tmp_path / "missing.npz")
    truncated = tmp_path / "trunc.npz"
    truncated.write_bytes(good.read_bytes()[:200])
    with pytest.raises(CheckpointError):
        load_checkpoint(truncated)
    with np.load(good) as data:
        arrays = {k: data[k] for k in data.files}
    np.savez(tmp_path / "noheader.npz", **{k: v for k, v in arrays.items() if k != "header"})
    with pytest.raises(CheckpointError, match="header"):
        load_checkpoint(tmp_path / "noheader.npz")
    wrong = dict(arrays, **{"filter.poses": np.zeros((5, 1, 3))})
    np.savez(tmp_path / "shape.npz", **wrong)
    with pytest.raises(CheckpointError, match="filter.poses"):
        load_checkpoint(tmp_path / "shape.npz")
    header = read_header(good)
    header["version"] = 99
    import json

    np.savez(tmp_path / "v99.npz", **dict(arrays, header=np.frombuffer(json.dumps(header).encode(), np.uint8)))
    with pytest.raises(CheckpointError, match="version"):
        load_checkpoint(tmp_path / "v99.npz")


def test_a_checkpoint_of_a_removed_option_still_loads(tmp_path):
    """A checkpoint written while the config had an option since removed (off, or gone for good)
    resumes with the current config."""
    import json

    slam = MultiRobotFastSLAM(FilterConfig(num_particles=10, seed=1), ["a"], np.zeros((1, 3)))
    path = save_checkpoint(slam, tmp_path / "old.npz")
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(arrays["header"].tobytes().decode("utf-8"))
    header["config"]["weight_gain"] = 1.0
    header["config"]["association"]["best_pair"] = False
    arrays["header"] = np.frombuffer(json.dumps(header).encode("utf-8"), np.uint8)
    np.savez(path, **arrays)
    copy, _ = load_checkpoint(path)
    assert copy.config == slam.config
