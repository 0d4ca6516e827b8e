"""The compiled kernels of the filter against plain numpy written here: the stereo gate, EKF update
and FastSLAM 2.0 terms, the ML association cost, the proposal sums and the landmark store's
copy-on-write write. Frames: map x, y in the ground plane, z up; poses (x, y, θ)."""

import numpy as np
import pytest

from mrslam_core.slam import stereo_kernels
from mrslam_core.slam.association_kernels import ml_cost
from mrslam_core.slam.landmarks import LandmarkStore
from mrslam_core.slam.models import ObservationModel, StereoPointModel
from mrslam_core.slam.proposal_kernels import sum_terms
from mrslam_core.slam.store_kernels import copy_table_rows, plan_chunks


def _rz(theta):
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _spd(rng, n, scale=0.01):
    a = rng.standard_normal((n, 3, 3))
    return a @ a.transpose(0, 2, 1) * scale + scale * np.eye(3)


def test_update_of_a_hand_computed_pair():
    # robot at the origin facing +x (Rz = I), Σ = R = I: S = 2I, gain ½, Σ' = ½I, D = |ν|²/2
    model = StereoPointModel()
    mu = np.array([[2.0, 1.0, 0.5]])
    z = np.array([[2.4, 0.8, 0.7]])  # ν = (0.4, −0.2, 0.2)
    new_mu, new_sig, maha, norm = model.update(np.zeros((1, 3)), z, np.eye(3)[None], mu, np.eye(3)[None])
    np.testing.assert_allclose(new_mu, [[2.2, 0.9, 0.6]], atol=1e-15)
    np.testing.assert_allclose(new_sig, 0.5 * np.eye(3)[None], atol=1e-15)
    assert maha[0] == pytest.approx(0.24 / 2, abs=1e-15)
    assert norm[0] == pytest.approx(3 * np.log(2 * np.pi) + np.log(8.0), abs=1e-12)


def test_gate_reads_the_pools_and_equals_the_matrix_form():
    rng = np.random.default_rng(0)
    m, b, v, rows_in_pool = 4, 3, 5, 11
    model = StereoPointModel()
    pose = np.column_stack([rng.uniform(-1, 1, (m, 2)), rng.uniform(-3, 3, m)])
    z = rng.uniform(-3, 3, (b, 3))
    r = _spd(rng, b)
    mean = rng.uniform(-3, 3, (rows_in_pool, 3)).astype(np.float32)
    cov = _spd(rng, rows_in_pool).astype(np.float32)
    rows = rng.integers(0, rows_in_pool, (m, v))
    vb = rng.integers(0, b, v)
    p_cov = _spd(rng, m)
    for pc in (None, p_cov):
        maha, norm = model.score_rows(pose, z, r, mean, cov.reshape(-1, 9), rows, vb, pc)
        for i in range(m):
            for j in range(v):
                mu, sig = mean[rows[i, j]].astype(float), cov[rows[i, j]].astype(float)
                rot = _rz(pose[i, 2])
                s = sig + rot @ r[vb[j]] @ rot.T
                if pc is not None:  # Hₓ P Hₓᵀ with Hₓ = ∂(g⁻¹(x, z) − μ)/∂x taken at μ
                    h = np.array([[-1.0, 0.0, mu[1] - pose[i, 1]], [0.0, -1.0, -(mu[0] - pose[i, 0])], [0, 0, 0]])
                    s = s + h @ pc[i] @ h.T
                nu = np.array([pose[i, 0], pose[i, 1], 0.0]) + rot @ z[vb[j]] - mu
                assert maha[i, j] == pytest.approx(nu @ np.linalg.solve(s, nu), rel=1e-11)
                assert norm[i, j] == pytest.approx(3 * np.log(2 * np.pi) + np.log(np.linalg.det(s)), rel=1e-12)


def test_gate_with_pose_uncertainty_equals_the_generic_robot_frame_score():
    rng = np.random.default_rng(1)
    n = 30
    model = StereoPointModel()
    pose = np.column_stack([rng.uniform(-1, 1, (n, 2)), rng.uniform(-3, 3, n)])
    mu = rng.uniform(-5, 5, (n, 3))
    sig, r, p_cov = _spd(rng, n), _spd(rng, n), _spd(rng, n)
    z = model.predict(pose, mu)[0] + 0.1 * rng.standard_normal((n, 3))
    got = model.score(pose, z, r, mu, sig, p_cov)
    want = ObservationModel.score(model, pose, z, r, mu, sig, p_cov)
    for g, w in zip(got, want):
        np.testing.assert_allclose(g, w, rtol=1e-10)


def test_proposal_terms_equal_the_generic_ones():
    # the kernel works in the map frame; HₓᵀZ⁻¹Hₓ, HₓᵀZ⁻¹ν, νᵀZ⁻¹ν and |Z| do not depend on it,
    # nor does the residual νᵀZ⁻¹ν after a shift dx (the outlier test)
    rng = np.random.default_rng(2)
    n = 25
    model = StereoPointModel()
    x = np.column_stack([rng.uniform(-1, 1, (n, 2)), rng.uniform(-3, 3, n)])
    dx = 0.05 * rng.standard_normal((n, 3))
    mu = rng.uniform(-5, 5, (n, 3))
    sig, r = _spd(rng, n), _spd(rng, n)
    z = model.predict(x, mu)[0] + 0.1 * rng.standard_normal((n, 3))
    pairs = np.arange(n)
    mean, cov = mu.astype(np.float32), sig.astype(np.float32).reshape(n, 9)  # as the pools hold them
    got = model.proposal_terms(x, dx, z, r, pairs, pairs, mean, cov, pairs)
    want = ObservationModel.proposal_terms(model, x, dx, z, r, pairs, pairs, mean, cov, pairs)
    for g, w in zip(got[:4], want[:4]):
        np.testing.assert_allclose(g, w, rtol=1e-9, atol=1e-12)
    shift = 0.1 * rng.standard_normal((n, 3))

    def residual(nu, zinv, hx):
        e = nu - (hx @ shift[..., None])[..., 0]
        return np.einsum("pi,pij,pj->p", e, zinv, e)

    np.testing.assert_allclose(residual(*got[4:]), residual(*want[4:]), rtol=1e-9)
    # without residuals (no outlier gate): the same sums' terms bit for bit, ν, Z⁻¹, Hₓ empty
    lean = model.proposal_terms(x, dx, z, r, pairs, pairs, mean, cov, pairs, residuals=False)
    for g, w in zip(lean[:4], got[:4]):
        np.testing.assert_array_equal(g, w)
    assert [a.shape[0] for a in lean[4:]] == [0, 0, 0]


def test_ml_cost_equals_the_numpy_rule():
    rng = np.random.default_rng(3)
    m, b, v = 6, 4, 12
    maha = rng.uniform(0, 20, (m, v))
    maha[0, 0] = np.nan  # a singular S fails every gate
    held = rng.random((m, v)) < 0.8
    confirmed = held & (rng.random((m, v)) < 0.7)
    ev = rng.uniform(0, 0.5, v)
    vb = np.sort(rng.integers(0, b, v))
    vslots = rng.integers(0, 5, v)
    track_slot = rng.integers(-1, 5, (m, b))
    d0, w, trust, track_gate = 11.34, 0.05, 16.0, 14.0
    feasible = held & (maha <= d0)
    want = np.where(feasible, ev[None] + w * maha, np.inf)
    want = np.where(feasible & ~confirmed, want + 1e3, want)
    want = np.where(held & ~feasible & (maha <= trust), 1e6 + maha, want)
    want = np.where((vslots[None] == track_slot[:, vb]) & held & (maha <= track_gate), -1.0, want)
    got = np.empty((m, v))
    ml_cost(maha, held, confirmed, ev, d0, w, trust, track_slot, vslots, vb, track_gate, got)
    np.testing.assert_array_equal(got, want)
    # trust gate and track memory off
    want = np.where(feasible, ev[None] + w * maha, np.inf)
    want = np.where(feasible & ~confirmed, want + 1e3, want)
    ml_cost(maha, held, confirmed, ev, d0, w, 0.0, np.zeros((0, 0), np.int64), vslots, vb, track_gate, got)
    np.testing.assert_array_equal(got, want)


def test_sum_terms_equals_bincount_bit_for_bit():
    rng = np.random.default_rng(4)
    index = rng.integers(0, 7, 500)
    values = rng.standard_normal((500, 14)) * 10.0 ** rng.integers(-8, 8, (500, 14))
    want = np.stack([np.bincount(index, values[:, c], 9) for c in range(14)], axis=1)
    got = sum_terms(index, np.ascontiguousarray(values[:, :9]), np.ascontiguousarray(values[:, 9:12]),
                    values[:, 12].copy(), values[:, 13].copy(), 9)
    np.testing.assert_array_equal(np.column_stack(got), want)


def test_plan_chunks_gives_each_shared_chunk_the_rank_of_its_last_occurrence():
    # nodes 0, 1 of 2 chunk columns; chunk 5 is shared (refcount 2), chunks 6, 7 private
    nodes = np.array([[5, 6], [5, 7]])
    refcount = np.zeros(8, np.int64)
    refcount[[5, 6, 7]] = [2, 1, 1]
    nid = np.array([1, 0, 1, 0, 0, 1])
    sub = np.array([0, 0, 1, 1, 0, 0])
    scratch = np.full(4, -1, np.int64)
    target = np.empty(6, np.int64)
    n = plan_chunks(nodes, refcount, nid, sub, scratch, target)
    # shared keys (node 1, col 0) last at pair 5 and (node 0, col 0) last at pair 4: ranks 1 and 0
    assert n == 2
    np.testing.assert_array_equal(target, [1, 0, -1, -1, 0, 1])
    np.testing.assert_array_equal(scratch, -1)


def test_write_copies_shared_chunks_once_and_in_order():
    store = LandmarkStore(3, 3, 0, capacity=64, chunk=4, fanout=2)
    slots = store.allocate(10, None)
    store.write(np.zeros(10, int), slots, mean=np.arange(30.0).reshape(10, 3), exists=True, count=2)
    store.copy_rows(np.array([1, 2]), np.array([0, 0]))  # all three share particle 0's map
    before = store.chunk_table().copy()
    free = store._free_chunks.ids[-3:].copy()  # the three chunks the write will take
    pm = np.array([1, 1, 2, 1])
    ps = np.array([0, 1, 5, 9])
    rows = store.write(pm, ps, mean=np.full((4, 3), -1.0), score=np.array([1, 2, 3, 4]))
    after = store.chunk_table()
    # particle 1 copies columns 0 and 2, particle 2 column 1; the last occurrence of each
    # (particle, column) is its representative, and representatives take the free chunks in
    # pair order: (1, col 0) at pair 1, (2, col 1) at pair 2, (1, col 2) at pair 3
    assert [after[1, 0], after[2, 1], after[1, 2]] == free.tolist()
    np.testing.assert_array_equal(after[0], before[0])
    np.testing.assert_array_equal(rows, [after[1, 0] * 4, after[1, 0] * 4 + 1, after[2, 1] * 4 + 1, after[1, 2] * 4 + 1])
    mean, score, count = store.gather(np.arange(3)[:, None], slots[None], ("mean", "score", "count"))
    want = np.broadcast_to(np.arange(30.0).reshape(10, 3), (3, 10, 3)).copy()
    want[pm, ps] = -1.0
    np.testing.assert_array_equal(mean, want)
    want_score = np.zeros((3, 10))
    want_score[pm, ps] = [1, 2, 3, 4]
    np.testing.assert_array_equal(score, want_score)
    np.testing.assert_array_equal(count, 2)  # copied with the chunk, not written
    assert store.check() == []


def test_gathered_rows_equal_the_table_lookup():
    rng = np.random.default_rng(5)
    store = LandmarkStore(5, 2, 0, capacity=8, chunk=4, fanout=3)
    slots = store.allocate(30, None)
    for p in range(5):
        pick = rng.random(30) < 0.5
        store.write(np.full(pick.sum(), p), slots[pick], mean=rng.standard_normal((pick.sum(), 2)), exists=True)
    col = slots // 4
    want = store.nodes[store.table[:, col // 3], col % 3] * 4 + slots % 4
    np.testing.assert_array_equal(store.rows(np.arange(5)[:, None], slots[None]), want)
    m = rng.integers(0, 5, 17)
    s = rng.integers(0, 30, 17)
    c = s // 4
    np.testing.assert_array_equal(store.rows(m, s), store.nodes[store.table[m, c // 3], c % 3] * 4 + s % 4)


def test_copy_table_rows_counts_references_as_whole_array_counting_does():
    # the numpy reference: count the new references, then drop the old ones; sources may be
    # destinations too (select_particles), so the rows are read before any is written
    rng = np.random.default_rng(6)
    table = rng.integers(0, 9, (6, 4))
    node_ref = np.bincount(table.ravel(), minlength=9)
    dst = np.arange(6)
    src = rng.integers(0, 6, 6)
    want_table = table[src]
    want_ref = node_ref + np.bincount(want_table.ravel(), minlength=9) - np.bincount(table.ravel(), minlength=9)
    want_dead = np.flatnonzero((node_ref > 0) & (want_ref == 0))
    got_table, got_ref = table.copy(), node_ref.copy()
    dead = copy_table_rows(got_table, got_ref, dst, table[src])
    np.testing.assert_array_equal(got_table, want_table)
    np.testing.assert_array_equal(got_ref, want_ref)
    np.testing.assert_array_equal(np.sort(dead), want_dead)


def test_held_slots_is_the_union_over_particles():
    rng = np.random.default_rng(7)
    store = LandmarkStore(6, 2, 0, capacity=8, chunk=4, fanout=2)
    slots = store.allocate(37, None)
    for p in range(6):
        pick = rng.random(37) < 0.2
        store.write(np.full(pick.sum(), p), slots[pick], exists=True)
    store.copy_rows(np.array([4, 5]), np.array([0, 0]))
    (ex,) = store.gather(np.arange(6)[:, None], slots[None], ("exists",))
    np.testing.assert_array_equal(store.held(), ex.any(axis=0))



@pytest.mark.parametrize("kind", ["default", "team", "mrclam"])
def test_warm_up_loads_every_kernel_a_filter_steps(kind):
    """After the warm-up, the filter's steps call no kernel for the first time: a second warm-up
    with another number of landmarks (same types) adds no signature to any dispatcher."""
    from mrslam_core.pipelines.mrclam import MrclamConfig
    from mrslam_core.pipelines.team import TeamConfig
    from mrslam_core.slam import association_kernels, proposal_kernels, store_kernels
    from mrslam_core.slam.config import FilterConfig
    from mrslam_core.slam.warmup import warm_up

    cfg = {"default": FilterConfig, "team": lambda: TeamConfig().filter, "mrclam": lambda: MrclamConfig().filter}[kind]()
    assert warm_up(cfg) > 0
    dispatchers = [getattr(m, n) for m in (association_kernels, proposal_kernels, stereo_kernels, store_kernels)
                   for n in dir(m) if hasattr(getattr(m, n), "signatures")]
    before = {d.__name__: len(d.signatures) for d in dispatchers}
    assert sum(before.values()) > 0
    warm_up(cfg, landmarks=7)
    assert {d.__name__: len(d.signatures) for d in dispatchers} == before


def test_new_landmark_rows_equal_new_landmark_bit_for_bit():
    rng = np.random.default_rng(7)
    m, b, p = 9, 5, 30
    pose = np.column_stack([rng.uniform(-3, 3, (m, 2)), rng.uniform(-3, 3, m)])
    z = rng.uniform(-4, 4, (b, 3))
    r = _spd(rng, b)
    pi, bi = rng.integers(0, m, p), rng.integers(0, b, p)
    model = StereoPointModel()
    got = model.new_landmark_rows(pose, z, r, pi, bi)
    want = model.new_landmark(pose[pi], z[bi], r[bi])
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g, w)
