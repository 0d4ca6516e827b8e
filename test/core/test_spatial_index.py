"""The landmark search indexes answer exactly as a kd-tree over the current positions and
descriptors would, however the slots moved, appeared or died; and a store saved in the
one-level layout loads into the two-level one with every value in place."""

import numpy as np
from scipy.spatial import cKDTree

from mrslam_core.slam.landmarks import LandmarkStore
from mrslam_core.slam.resampling import copy_plan
from mrslam_core.slam.spatial_index import DescriptorIndex, PositionGrid


def _tree_answer(pos, live, points, k, radius):
    tree = cKDTree(pos[live])
    d, i = tree.query(points, k=k, distance_upper_bound=radius)
    d, i = d.reshape(len(points), k), i.reshape(len(points), k)
    return np.where(np.isfinite(d), live[np.minimum(i, live.size - 1)], -1)


def test_grid_matches_a_kdtree_after_moves_births_and_deaths():
    rng = np.random.default_rng(1)
    n = 2000
    pos = np.full((n, 3), np.inf)
    grid = PositionGrid(cell=0.7)
    for step in range(30):
        born = rng.choice(n, 60)
        moved = rng.choice(n, 80)
        died = rng.choice(n, 10)
        new = pos.copy()
        new[born] = rng.uniform(-15, 15, (born.size, 3))
        new[moved] = np.where(np.isfinite(pos[moved]), pos[moved] + rng.normal(0, 0.4, (moved.size, 3)), np.inf)
        new[died] = np.inf
        changed = np.unique(np.concatenate([born, moved, died]))
        pos = new
        grid.update(changed, pos[changed])
        live = np.flatnonzero(np.isfinite(pos[:, 0]))
        points = rng.uniform(-16, 16, (20, 3))
        for radius in (0.3, 1.5, 4.0, np.inf):
            got = grid.nearest(pos, points, 8, radius)
            np.testing.assert_array_equal(got, _tree_answer(pos, live, points, 8, radius))
        ball = cKDTree(pos[live]).query_ball_point(points[0], 3.0)
        np.testing.assert_array_equal(grid.within(pos, points[0], 3.0), np.sort(live[ball]))


def test_grid_survives_bad_positions_and_queries():
    grid = PositionGrid()
    pos = np.array([[1.0, 1.0, 0.0], [1e300, -1e300, 0.0], [np.nan, 0.0, 0.0], [2.0, 1.0, 0.0]])
    grid.update(np.arange(4), pos)
    assert grid.nearest(pos, np.array([[1.1, 1.0, 0.0]]), 3, 2.0).tolist() == [[0, 3, -1]]
    assert grid.nearest(pos, np.array([[np.nan, 0.0, 0.0]]), 2, 2.0).tolist() == [[-1, -1]]
    assert grid.nearest(pos, np.array([[0.0, 0.0, 0.0]]), 2, 1e200).tolist() == [[0, 3]]


def test_descriptor_index_matches_brute_force_as_slots_are_added():
    rng = np.random.default_rng(2)
    desc = rng.standard_normal((900, 16)).astype(np.float32)
    index = DescriptorIndex(rebuild_after=50)
    live = np.zeros(0, np.int64)
    for start in range(0, 900, 30):
        added = np.arange(start, start + 30)
        live = np.concatenate([live, added])
        index.add(added)
        q = desc[rng.choice(live, 12)] + rng.normal(0, 0.3, (12, 16))
        got = index.nearest(desc, live, q, 5, 4.5)
        d = np.linalg.norm(q[:, None] - desc[live][None], axis=2)
        order = np.argsort(d, axis=1, kind="stable")[:, :5]
        want = np.where(np.take_along_axis(d, order, 1) < 4.5, live[order], -1)
        np.testing.assert_array_equal(got, want)


def test_one_level_state_loads_with_every_value():
    rng = np.random.default_rng(3)
    m = 6
    store = LandmarkStore(m, 3, 0, capacity=8, chunk=4, fanout=2)
    for _ in range(40):
        slots = store.allocate(int(rng.integers(1, 4)), None)
        pm = rng.integers(0, m, slots.size)
        store.write(pm, slots, mean=rng.standard_normal((slots.size, 3)), exists=True, count=2)
        dst, src = copy_plan(np.sort(rng.integers(0, m, m)))
        store.copy_rows(dst, src)
    state = store.state()
    one_level = {"table": store.chunk_table()} | {k: v for k, v in state.items() if k not in ("table", "nodes", "node_ref")}
    loaded = LandmarkStore.from_state(one_level, 3, 4, 0, store.size, fanout=2)
    assert loaded.check() == []
    rows, slots = np.arange(m)[:, None], np.arange(store.size)[None]
    for a, b in zip(store.gather(rows, slots, ("mean", "exists", "count")),
                    loaded.gather(rows, slots, ("mean", "exists", "count"))):
        np.testing.assert_array_equal(a, b)
    # particles that shared a chunk still share one after the load (plus the pinned empty chunk)
    assert int((loaded.refcount > 0).sum()) <= np.unique(store.chunk_table()).size + 1
