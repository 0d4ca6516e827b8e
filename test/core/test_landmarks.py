"""The copy-on-write landmark store: equal to a dense per-particle copy under any sequence of
writes, resamplings and compactions, and resampled particles never share what they write."""

import numpy as np

from mrslam_core.slam.landmarks import LandmarkStore
from mrslam_core.slam.resampling import copy_plan, low_variance_indices


def test_random_operations_match_dense_reference():
    rng = np.random.default_rng(0)
    m, dim = 7, 2
    store = LandmarkStore(m, dim, 0, capacity=4, chunk=4, fanout=3)
    ref_mean = np.zeros((m, 0, dim))
    ref_ex = np.zeros((m, 0), bool)
    for _ in range(400):
        op = rng.integers(0, 4)
        if op == 0 or store.size == 0:
            n = int(rng.integers(1, 6))
            store.allocate(n, None)
            ref_mean = np.concatenate([ref_mean, np.zeros((m, n, dim))], 1)
            ref_ex = np.concatenate([ref_ex, np.zeros((m, n), bool)], 1)
        elif op == 1:
            key = np.unique(rng.integers(0, m * store.size, int(rng.integers(1, 15))))
            pm, ps = key // store.size, key % store.size
            v = rng.standard_normal((key.size, dim)).astype(np.float32)  # the pool stores float32
            store.write(pm, ps, mean=v, exists=True)
            ref_mean[pm, ps] = v
            ref_ex[pm, ps] = True
        elif op == 2:
            dst, src = copy_plan(np.sort(rng.integers(0, m, m)))
            store.copy_rows(dst, src)
            ref_mean[dst] = ref_mean[src]
            ref_ex[dst] = ref_ex[src]
        elif store.dead_fraction() > 0.3:
            keep = store.compact() >= 0
            ref_mean, ref_ex = ref_mean[:, keep], ref_ex[:, keep]
        g_mean, g_ex = store.gather(np.arange(m)[:, None], np.arange(store.size)[None], ("mean", "exists"))
        np.testing.assert_array_equal(g_ex, ref_ex)
        np.testing.assert_array_equal(g_mean[ref_ex], ref_mean[ref_ex])
        assert store.check() == []  # reference counts match the tables, the empty chunk stays empty
        np.testing.assert_array_equal(store.held(), ref_ex.any(axis=0))


def test_resampled_copies_do_not_alias():
    store = LandmarkStore(4, 3, 0, capacity=8)
    slots = store.allocate(3, None)
    store.write(np.zeros(3, int), slots, mean=np.ones((3, 3)), exists=True)
    dst, src = copy_plan(np.array([0, 0, 0, 0]))  # every particle a copy of particle 0
    store.copy_rows(dst, src)
    store.write(np.array([2]), slots[:1], mean=np.array([[9.0, 9.0, 9.0]]))
    means = store.gather(np.arange(4)[:, None], slots[None], ("mean",))[0]
    assert means[2, 0].tolist() == [9.0, 9.0, 9.0]
    for p in (0, 1, 3):
        assert means[p, 0].tolist() == [1.0, 1.0, 1.0]
    # and the underlying arrays of particle 2 are not those of the others for the written chunk
    assert store.chunk_table()[2, 0] != store.chunk_table()[0, 0]


def test_copy_plan_reproduces_the_drawn_population():
    rng = np.random.default_rng(5)
    index = low_variance_indices(np.log(rng.dirichlet(np.ones(50))), rng)
    rows = np.arange(50)
    dst, src = copy_plan(index)
    rows[dst] = rows[src]
    assert sorted(rows.tolist()) == sorted(index.tolist())


def test_candidates_nearest_first_within_radius():
    store = LandmarkStore(2, 2, 0, capacity=8)
    slots = store.allocate(4, None)
    pos = np.array([[0.0, 0.0], [1.0, 0.0], [5.0, 0.0], [0.3, 0.0]])
    for p in range(2):
        store.write(np.full(4, p), slots, mean=pos, exists=True)
    store.refresh_reference(slots)
    got = store.candidates(np.array([[0.1, 0.0]]), k=3, radius=1.5)
    assert got.tolist() == [[0, 3, 1]]
