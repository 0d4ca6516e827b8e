"""Generated buildings: deterministic, within the size range, valid and connected, textured with
look-alike and texture-poor walls, and named wherever a world is named."""

import numpy as np
import pytest

from mrslam_core.sim import SimConfig, SimError, Simulation, load_world
from mrslam_core.sim.world import REACH_RADIUS, free_components
from mrslam_core.sim.worldgen import KINDS, SIZE_MAX, SIZE_MIN, START_MODES, generate, suite


def test_same_seed_same_world_other_seed_other_world():
    assert generate("office", 7) == generate("office", 7)
    assert generate("office", 7)["walls"] != generate("office", 8)["walls"]
    # the start mode draws the start poses only: the same building
    together, apart = generate("ring", 3), generate("ring", 3, starts="apart")
    assert together["walls"] == apart["walls"] and together["boxes"] == apart["boxes"]
    assert together["start_poses"] != apart["start_poses"]


@pytest.mark.parametrize("kind", KINDS)
def test_every_kind_is_valid_connected_and_textured(kind):
    for seed in (0, 1, 2):
        for mode in START_MODES:
            world = load_world(generate(kind, seed, starts=mode))  # load_world checks walls and start poses
            assert all(SIZE_MIN[k] <= world.size[k] <= SIZE_MAX[k] for k in (0, 1)), world.size
            # one connected free space for a robot's centre, all of it reached from the start poses
            labels = free_components(world.occupancy(0.1, inflate=REACH_RADIUS))
            sizes = np.bincount(labels.ravel())[1:]
            assert sizes.max() >= 0.995 * sizes.sum(), (world.name, sorted(sizes)[-3:])
            occ = world.occupancy(0.1)
            assert world.reachable_free(0.1).sum() >= 0.98 * (~occ).sum(), world.name
            assert {"plain", "repetitive", "unique"} <= set(world.wall_textures), world.name
            starts = world.start_poses
            gaps = np.linalg.norm(starts[:, None, :2] - starts[None, :, :2], axis=2)[np.triu_indices(len(starts), 1)]
            if mode == "together":  # a zig-zag column, neighbours 1 m apart
                np.testing.assert_allclose(np.linalg.norm(np.diff(starts[:, :2], axis=0), axis=1), 1.0, atol=0.02)
                assert np.ptp(starts[:, 2]) == 0
            else:
                assert gaps.min() > 3.0, (world.name, gaps.min())


def test_sizes_drawn_across_the_range_or_as_given():
    sizes = np.array([load_world(f"gen:{KINDS[s % 4]}:{s}").size for s in range(16)])
    assert (sizes >= SIZE_MIN).all() and (sizes <= SIZE_MAX).all()
    assert np.ptp(sizes[:, 0]) > 15 and np.ptp(sizes[:, 1]) > 8
    assert load_world(generate("warehouse", 1, size=(12.0, 20.0))).size == (12.0, 20.0)  # laid out along y
    with pytest.raises(SimError, match="at least 10 x 10 m"):
        generate("open", 1, size=(8.0, 20.0))


def test_names_and_the_suite():
    world = load_world("gen:ring:3:apart")
    assert world.name == "gen:ring:3:apart" and len(world.start_poses) == 4
    assert len(load_world("gen:office:2:together:6").start_poses) == 6
    for bad, words in (("gen:castle:1", "kind must be one of"), ("gen:office:x", "whole numbers"),
                       ("gen:office:1:scattered", "start mode"), ("gen:office", "gen:KIND:SEED")):
        with pytest.raises(SimError, match=words):
            load_world(bad)
    names = suite(8)
    assert [n.split(":")[1] for n in names[:4]] == list(KINDS)
    for kind in KINDS:  # each kind with both start modes
        assert {n.split(":")[3] for n in names if n.split(":")[1] == kind} == set(START_MODES)


def test_the_simulator_takes_a_generated_world():
    sim = Simulation(SimConfig(world="gen:warehouse:1"))
    try:
        sim.add_robot("robot1")
        np.testing.assert_allclose(sim.ground_truth("robot1"), load_world("gen:warehouse:1").start_poses[0], atol=1e-6)
    finally:
        sim.close()
