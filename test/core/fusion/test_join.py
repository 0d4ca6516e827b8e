"""Joining a robot's own filter (K = 1, its own frame) into the central filter, particle by particle
(004 section 5)."""

from dataclasses import replace

import numpy as np
import pytest

from mrslam_core.datasets.synthetic import SyntheticWorld, SyntheticWorldConfig
from mrslam_core.fusion.config import FusionConfig
from mrslam_core.fusion.acceptance import JoinGate
from mrslam_core.fusion.join import join_filters, move_landmarks, try_join
from mrslam_core.geometry.se2 import between, compose, wrap_angle
from mrslam_core.slam.config import FilterConfig
from mrslam_core.slam.filter import MultiRobotFastSLAM

T = np.array([2.0, -1.0, 0.6])  # local frame -> central map frame


def spd(rng, n):
    a = rng.standard_normal((n, 3, 3)) * 0.1
    return a @ a.transpose(0, 2, 1) + 0.01 * np.eye(3)


def hand_filters(seed=0):
    """Central: 6 particles, robot 'a', 3 landmarks (descriptors e0 e1 e2; particle 5 lacks e1).
    Local: 4 particles, robot 'b', 4 landmarks (e0 e1 shared with central, e3 e4 new; particle 3
    lacks e3)."""
    rng = np.random.default_rng(seed)
    eye = np.eye(5, dtype=np.float32)
    central = MultiRobotFastSLAM(FilterConfig(num_particles=6, seed=seed), ["a"], np.zeros((1, 3)))
    central.poses[:, 0] = rng.normal(0, 1, (6, 3))
    ex = np.ones((6, 3), bool)
    ex[5, 1] = False
    central.insert_landmarks(rng.normal(0, 3, (6, 3, 3)), spd(rng, 18).reshape(6, 3, 3, 3), ex, eye[:3],
                             np.full((6, 3), 2))
    central.log_w = np.log(np.array([0.3, 0.1, 0.2, 0.1, 0.2, 0.1]))
    local = MultiRobotFastSLAM(FilterConfig(num_particles=4, seed=seed + 1), ["b"], np.zeros((1, 3)))
    local.poses[:, 0] = rng.normal(0, 1, (4, 3))
    ex = np.ones((4, 4), bool)
    ex[3, 2] = False
    local.insert_landmarks(rng.normal(0, 3, (4, 4, 3)), spd(rng, 16).reshape(4, 4, 3, 3), ex, eye[[0, 1, 3, 4]])
    local.log_w = np.log(np.array([0.4, 0.3, 0.2, 0.1]))
    local.last_stamp["b"] = 7_000_000_000
    return central, local


def test_a_join_leaves_every_mapped_robot_and_landmark_bit_identical():
    """The join only adds the newcomer: every central particle keeps its poses, weight and map
    exactly (no resampling, matched landmarks keep the common copy); the joined robot sits at its
    local pose moved by T; the local-only landmarks are added, moved."""
    central, local = hand_filters()
    c_poses, c_w = central.poses.copy(), central.log_w.copy()
    c_lm = central.landmarks.gather(np.arange(6)[:, None], np.arange(3)[None], ("mean", "cov", "exists", "count"))
    l_lm = local.landmarks.gather(np.arange(4)[:, None], np.arange(4)[None], ("mean", "cov", "exists"))
    res = join_filters(central, local, T, np.array([[0, 0], [1, 1]]), FusionConfig())
    ic, il = res.ancestors.T
    assert central.poses.shape == (6, 2, 3) and central.robots == ["a", "b"]
    np.testing.assert_array_equal(ic, np.arange(6))
    np.testing.assert_array_equal(central.poses[:, 0], c_poses[:, 0])
    np.testing.assert_array_equal(central.log_w, c_w)
    np.testing.assert_allclose(central.poses[:, 1], compose(T, local.poses[il, 0]), atol=1e-12)
    assert central.last_stamp["b"] == 7_000_000_000
    mean, cov, ex, cnt = central.landmarks.gather(np.arange(6)[:, None], np.arange(3)[None], ("mean", "cov", "exists", "count"))
    held = c_lm[2]
    for got, was in zip((mean, cov, cnt), (c_lm[0], c_lm[1], c_lm[3])):
        np.testing.assert_array_equal(got[held], was[held])
    # particle 5 lacked e1 (slot 1): it gets its local ancestor's copy, moved
    ml, sl = move_landmarks(T, l_lm[0].astype(float), l_lm[1].astype(float))
    assert ex[5, 1]
    np.testing.assert_allclose(mean[5, 1], ml[il[5], 1], atol=1e-5)
    np.testing.assert_allclose(cov[5, 1], sl[il[5], 1], atol=1e-6)
    assert res.fused == 2 and res.added == 2 and res.slot_map.tolist() == [0, 1, 3, 4]
    new_mean, new_ex = central.landmarks.gather(np.arange(6)[:, None], np.array([3, 4])[None], ("mean", "exists"))
    np.testing.assert_array_equal(new_ex[:, 0], il != 3)
    np.testing.assert_allclose(new_mean[new_ex], ml[il][:, 2:][new_ex], atol=1e-5)
    np.testing.assert_array_equal(central.landmarks.descriptor[4], np.eye(5, dtype=np.float32)[4])


def test_every_local_particle_is_drawn_by_its_weight():
    """50 equally weighted local particles at different poses: each is paired with one central
    particle (the grid draw over the M × L pairs once took ONE of them for all)."""
    c = MultiRobotFastSLAM(FilterConfig(num_particles=50, seed=1), ["a"], np.zeros((1, 3)))
    loc = MultiRobotFastSLAM(FilterConfig(num_particles=50, seed=2), ["b"], np.zeros((1, 3)))
    loc.poses[:, 0, 0] = np.arange(50.0)
    res = join_filters(c, loc, T, np.zeros((0, 2)), FusionConfig())
    assert np.unique(res.ancestors[:, 1]).size == 50
    loc.log_w = np.log(np.r_[np.full(10, 0.09), np.full(40, 0.1 / 40)])
    c = MultiRobotFastSLAM(FilterConfig(num_particles=1000, seed=1), ["a"], np.zeros((1, 3)))
    loc2 = MultiRobotFastSLAM(FilterConfig(num_particles=50, seed=2), ["b"], np.zeros((1, 3)))
    loc2.log_w = loc.log_w
    res = join_filters(c, loc2, T, np.zeros((0, 2)), FusionConfig())
    assert abs(int((res.ancestors[:, 1] < 10).sum()) - 900) <= 1  # systematic: within 1 of M·w


def test_drift_and_pending_motion_noise_move_with_the_robot():
    central, local = hand_filters(5)
    d = np.diag([0.04, 0.01, 0.002])
    local.drift_cov[0] = d
    local.pending_cov[0] = 2 * d
    join_filters(central, local, T, np.array([[0, 0]]), FusionConfig())
    c, s = np.cos(T[2]), np.sin(T[2])
    j = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    np.testing.assert_allclose(central.drift_cov[1], j @ d @ j.T, atol=1e-15)
    np.testing.assert_allclose(central.pending_cov[1], 2 * j @ d @ j.T, atol=1e-15)
    # with the alignment's covariance, the drift grows by it (θ uncertainty with lever arm)
    central, local = hand_filters(5)
    local.drift_cov[0] = d
    cov_t = np.diag([0.01, 0.01, 0.001])
    join_filters(central, local, T, np.array([[0, 0]]), FusionConfig(), pose_cov=cov_t)
    extra = central.drift_cov[1] - j @ d @ j.T
    assert np.all(np.diag(extra) >= np.diag(cov_t) - 1e-15) and extra[2, 2] == pytest.approx(0.001)


def test_restarted_robot_rejoins_in_place():
    central, local = hand_filters(3)
    join_filters(central, local, T, np.array([[0, 0]]), FusionConfig())
    other = central.poses[:, 0].copy()
    # robot b restarts: a fresh local filter with a later stamp, joined with another transform
    _, again = hand_filters(4)
    again.last_stamp["b"] = 9_000_000_000
    t2 = np.array([-1.0, 0.5, -2.0])
    res = join_filters(central, again, t2, np.array([[0, 0]]), FusionConfig())
    assert central.robots == ["a", "b"] and central.poses.shape == (6, 2, 3)
    np.testing.assert_allclose(central.poses[:, 1], compose(t2, again.poses[res.ancestors[:, 1], 0]), atol=1e-12)
    np.testing.assert_array_equal(central.poses[:, 0], other[res.ancestors[:, 0]])
    assert central.last_stamp["b"] == 9_000_000_000


def test_joined_particles_do_not_alias():
    central, local = hand_filters(1)
    join_filters(central, local, T, np.array([[0, 0]]), FusionConfig())
    store = central.landmarks
    slots = np.arange(store.size)
    before = store.gather(np.arange(6)[:, None], slots[None], ("mean",))[0].copy()
    store.write(np.zeros(slots.size, int), slots, mean=np.full((slots.size, 3), 9.0))
    after = store.gather(np.arange(6)[:, None], slots[None], ("mean",))[0]
    np.testing.assert_array_equal(after[1:], before[1:])
    assert (after[0] == 9.0).all()


def test_pair_likelihood_weights_the_pairs_whose_maps_agree():
    central, local = hand_filters(2)
    # every central particle holds slots 0 and 1 at the same place; local particle 2 agrees with
    # it after the transform, the other local particles are 1 m off
    truth = np.array([[1.0, 2.0, 0.5], [3.0, -1.0, 1.0]])
    m = central.num_particles
    central.landmarks.write(np.repeat(np.arange(m), 2), np.tile([0, 1], m), mean=np.tile(truth, (m, 1)))
    in_local = between(T, np.column_stack([truth[:, :2], np.zeros(2)]))  # the landmarks in the local frame
    agree = np.column_stack([in_local[:, :2], truth[:, 2]])
    vals = np.repeat(agree[None], 4, axis=0) + np.array([1.0, 0.0, 0.0])
    vals[2] = agree
    local.landmarks.write(np.repeat(np.arange(4), 2), np.tile([0, 1], 4), mean=vals.reshape(-1, 3))
    res = join_filters(central, local, T, np.array([[0, 0], [1, 1]]), FusionConfig(pair_likelihood=True))
    w = np.exp(central.log_w)
    good = res.ancestors[:, 1] == 2
    assert good.any() and (~good).any()
    assert w[good].min() > 100 * w[~good].max()
    np.testing.assert_allclose(w.sum(), 1.0)
    # refitted per pair, the 1 m offset is absorbed by each pair's own transform
    central, local = hand_filters(2)
    central.landmarks.write(np.repeat(np.arange(m), 2), np.tile([0, 1], m), mean=np.tile(truth, (m, 1)))
    local.landmarks.write(np.repeat(np.arange(4), 2), np.tile([0, 1], 4), mean=vals.reshape(-1, 3))
    res = join_filters(central, local, T, np.array([[0, 0], [1, 1]]), FusionConfig(), per_pair=True)
    off = res.ancestors[:, 1] != 2
    np.testing.assert_allclose(res.transforms[~off], np.broadcast_to(T, ((~off).sum(), 3)), atol=1e-9)
    shift = T[:2] - np.array([[np.cos(T[2]), -np.sin(T[2])], [np.sin(T[2]), np.cos(T[2])]]) @ [1.0, 0.0]
    np.testing.assert_allclose(res.transforms[off, :2], np.broadcast_to(shift, (off.sum(), 2)), atol=1e-9)
    mean = central.landmarks.gather(np.arange(m)[:, None], np.array([0, 1])[None], ("mean",))[0]
    np.testing.assert_allclose(mean, np.broadcast_to(truth, (m, 2, 3)), atol=1e-5)


def test_robot_with_unknown_start_joins_the_team_filter():
    """Synthetic stereo world, 2 robots half a loop apart: robot2 maps from its own origin (K = 1),
    tries to join every 5 steps, is joined once its map overlaps robot1's, then runs in the
    central filter."""
    world_cfg = SyntheticWorldConfig(seed=1, num_robots=2, sigma_d=1.0, sigma_r=10.0, sigma_c=10.0)
    world = SyntheticWorld(world_cfg)
    fcfg = FilterConfig(num_particles=40, seed=3)
    starts = world.start_poses()
    central = MultiRobotFastSLAM(fcfg, ["robot1"], starts[:1])
    local = MultiRobotFastSLAM(replace(fcfg, seed=4), ["robot2"], np.zeros((1, 3)))
    err, reasons = [], []
    joined_at = None
    for i, (_, true, _, updates) in enumerate(world.run(110)):
        if joined_at is None:
            central.step(updates[:1])
            local.step(updates[1:])
            if i % 5 == 4:
                al, joined = try_join(central, local, FusionConfig())
                if joined is None:
                    reasons.append(al.reason)
                    continue
                joined_at = i
                # the joined robot is where it stands (the transform also holds the local map's
                # own drift since the robot's start, which its pose in that map shares)
                joined_pose = central.estimate().mean[1]
                assert np.hypot(*(joined_pose[:2] - true[1, :2])) < 0.15
                assert abs(wrap_angle(joined_pose[2] - true[1, 2])) < np.radians(2)
                assert abs(wrap_angle(al.transform[2] - starts[1, 2])) < np.radians(2)
                assert al.inliers.size >= 3  # two fix any transform; the chance test wants more when few agree
                # each joined particle: the local pose moved by that pair's own refitted transform
                np.testing.assert_allclose(
                    central.poses[:, 1], compose(joined.transforms, local.poses[joined.ancestors[:, 1], 0])
                )
                # each particle's own transform (refitted, then drawn from N(·, Cov T)) puts the robot
                # near where T does (the transforms' translations differ more: a rotation about the
                # local origin, 7 m away, moves them)
                at_t = compose(al.transform, local.estimate().mean[0])
                assert np.hypot(*(central.poses[:, 1, :2] - at_t[:2]).T).max() < 0.3
        else:
            central.step(updates)
            err.append(np.linalg.norm(central.estimate().poses[1, :2] - true[1, :2]))
    assert joined_at is not None and joined_at <= 105, reasons
    assert "descriptor matches" in reasons[0]  # the early attempts fail for the right reason
    assert central.robots == ["robot1", "robot2"] and central.num_particles == 40
    assert np.sqrt(np.mean(np.square(err))) < 0.15, err  # 0.035 m measured


def test_join_pose_sigma_spreads_the_joined_robot_around_its_moved_pose():
    central = MultiRobotFastSLAM(FilterConfig(num_particles=4000, seed=3), ["a"], np.zeros((1, 3)))
    local = MultiRobotFastSLAM(FilterConfig(num_particles=4, seed=4), ["b"], np.zeros((1, 3)))
    local.poses[:, 0] = np.random.default_rng(5).normal(0, 1, (4, 3))
    sigma = np.array([0.3, 0.2, 0.1])
    res = join_filters(central, local, T, np.zeros((0, 2)), FusionConfig(join_pose_sigma=tuple(sigma)))
    d = central.poses[:, 1] - compose(T, local.poses[res.ancestors[:, 1], 0])
    d[:, 2] = wrap_angle(d[:, 2])
    np.testing.assert_allclose(d.std(0), sigma, rtol=0.05)
    assert np.all(np.abs(d.mean(0)) < 4 * sigma / np.sqrt(4000))
    # the spread is part of the drift the robot enters with (none in the local filter here)
    np.testing.assert_allclose(central.drift_cov[1], np.diag(sigma**2), atol=1e-15)


def test_without_carrying_landmarks_only_the_robot_joins():
    central, local = hand_filters(6)
    size = central.landmarks.size
    c_lm = central.landmarks.gather(np.arange(6)[:, None], np.arange(size)[None], ("mean", "cov", "exists"))
    res = join_filters(central, local, T, np.array([[0, 0], [1, 1]]), FusionConfig(carry_landmarks=False))
    ic, il = res.ancestors.T
    assert central.robots == ["a", "b"] and central.landmarks.size == size
    assert res.fused == 0 and res.added == 0 and res.dropped == 4  # 2 matched + 2 local-only left out
    after = central.landmarks.gather(np.arange(6)[:, None], np.arange(size)[None], ("mean", "cov", "exists"))
    for a, b in zip(after, c_lm):
        np.testing.assert_array_equal(a, b[ic])
    np.testing.assert_allclose(central.poses[:, 1], compose(T, local.poses[il, 0]), atol=1e-12)


def test_per_pair_refit_keeps_the_transform_where_the_pair_cannot_fix_the_rotation():
    """Two matched landmarks 4 cm apart (in every particle) with local copies a little off: a
    refit on them would turn the robot by an arbitrary angle, so every pair keeps T; 3 m apart
    the same offsets are refitted."""
    for gap, refit in ((0.04, False), (3.0, True)):
        central, local = hand_filters(7)
        m = central.num_particles
        truth = np.array([[1.0, 2.0, 0.0], [1.0 + gap, 2.0, 0.0]])
        central.landmarks.write(np.repeat(np.arange(m), 2), np.tile([0, 1], m), mean=np.tile(truth, (m, 1)))
        in_local = between(T, truth)
        in_local[:, 2] = 0.0
        vals = np.repeat(in_local[None], 4, axis=0) + np.array([[0.02, 0.0, 0.0], [-0.02, 0.01, 0.0]])
        local.landmarks.write(np.repeat(np.arange(4), 2), np.tile([0, 1], 4), mean=vals.reshape(-1, 3))
        res = join_filters(central, local, T, np.array([[0, 0], [1, 1]]), FusionConfig(min_spread=0.5), per_pair=True)
        both = res.ancestors[:, 0] != 5  # central particle 5 lacks landmark 1
        moved = np.abs(res.transforms[both] - T).max()
        assert (moved > 1e-3) if refit else (moved == 0.0), (gap, moved)
        np.testing.assert_array_equal(res.transforms[~both], np.broadcast_to(T, ((~both).sum(), 3)))


def test_transform_uncertainty_into_the_proposal_and_the_moved_landmarks():
    """``proposal``: J_T Cov T J_Tᵀ at the robot's local position joins its pending motion
    covariance (and its drift), and each moved local landmark's x, y covariance grows by
    J_T Cov T J_Tᵀ at its own local position."""
    cov_t = np.diag([0.02, 0.01, 0.003])
    out = {}
    for mode in ("drift", "proposal"):
        central, local = hand_filters(8)
        local.poses[:, 0] = np.array([1.0, -2.0, 0.3])  # every particle at one local pose
        res = join_filters(central, local, T, np.array([[0, 0]]), FusionConfig(transform_uncertainty=mode),
                           pose_cov=cov_t)
        out[mode] = (central, local, res)
    jt = np.eye(3)
    c, s = np.cos(T[2]), np.sin(T[2])
    jt[:2, 2] = [-s * 1.0 - c * -2.0, c * 1.0 - s * -2.0]
    from_t = jt @ cov_t @ jt.T
    central, _, _ = out["drift"]
    assert 1 not in central.pending_cov
    np.testing.assert_allclose(central.drift_cov[1], from_t, atol=1e-15)
    central, local, res = out["proposal"]
    np.testing.assert_allclose(central.pending_cov[1], from_t, atol=1e-15)
    np.testing.assert_allclose(central.drift_cov[1], from_t, atol=1e-15)
    # a local-only landmark (local slot 3, held by every local particle): moved covariance + J Cov Jᵀ
    slot = res.slot_map[3]
    (cov_p,) = central.landmarks.gather(np.arange(6), np.full(6, slot), ("cov",))
    (cov_d,) = out["drift"][0].landmarks.gather(np.arange(6), np.full(6, out["drift"][2].slot_map[3]), ("cov",))
    il = res.ancestors[:, 1]
    (lm,) = local.landmarks.gather(il, np.full(6, 3), ("mean",))
    for n in range(6):
        j = np.array([[1.0, 0.0, -s * lm[n, 0] - c * lm[n, 1]], [0.0, 1.0, c * lm[n, 0] - s * lm[n, 1]]])
        np.testing.assert_allclose(cov_p[n, :2, :2] - cov_d[n, :2, :2], j @ cov_t @ j.T, atol=1e-6)
        np.testing.assert_allclose(cov_p[n, 2], cov_d[n, 2], atol=1e-7)


def test_an_ill_conditioned_alignment_is_weak_and_waits_for_agreeing_evidence():
    """Four shared landmarks within 0.6 m, 8 m from the robot: consistent (χ² tests), but the
    transform's error at the robot is far beyond the spread both filters hold (tr P_ref⁻¹P_T > 3):
    weak. With a gate (a pipeline with sightings) it is held, and a second alignment of the same
    maps does not confirm it; it is strong once the robots' own spreads cover it. Without a gate
    (no second source of evidence) it joins, and says it was weak."""
    cfg = FusionConfig()
    rng = np.random.default_rng(9)
    world = np.array([[5.0, 5.0], [5.6, 5.0], [5.0, 5.6], [5.6, 5.6], [5.3, 5.9]])
    eye = np.eye(5, dtype=np.float32)

    def filters(spread):
        central = MultiRobotFastSLAM(FilterConfig(num_particles=5, seed=1), ["a"], np.zeros((1, 3)))
        pts = np.column_stack([world + rng.normal(0, 0.005, world.shape), np.zeros(5)])
        central.insert_landmarks(np.broadcast_to(pts, (5, 5, 3)).copy(), np.broadcast_to(np.eye(3) * 1e-4, (5, 5, 3, 3)).copy(),
                                 np.ones((5, 5), bool), eye)
        central.pending_cov[0] = np.diag([spread, spread, spread / 10])
        local = MultiRobotFastSLAM(FilterConfig(num_particles=3, seed=2), ["b"], np.zeros((1, 3)))
        loc = between(T, np.column_stack([world + rng.normal(0, 0.005, world.shape), np.zeros(5)]))
        loc[:, 2] = 0.0
        local.insert_landmarks(np.broadcast_to(loc, (3, 5, 3)).copy(), np.broadcast_to(np.eye(3) * 1e-4, (3, 5, 3, 3)).copy(),
                               np.ones((3, 5), bool), eye)
        local.poses[:, 0] = between(T, np.array([-2.0, -1.0, 0.0]))  # 8 m from the landmarks
        return central, local

    gate = JoinGate.from_config(cfg)
    for t in (10.0, 15.0):
        central, local = filters(1e-4)
        al, joined = try_join(central, local, cfg, gate=gate, time_s=t)
        assert joined is None and al.inliers.size == 5 and "held" in al.reason
    assert central.robots == ["a"]
    central, local = filters(1.0)
    al, joined = try_join(central, local, cfg, gate=JoinGate.from_config(cfg), time_s=20.0)
    assert joined is not None and al.reason == ""
    central, local = filters(1e-4)
    al, joined = try_join(central, local, cfg)
    assert joined is not None and "without independent evidence" in al.reason and "weak evidence" in al.reason
    # every joined particle uses T (refitted per pair on its own landmark copies: here all equal)
    np.testing.assert_allclose(central.poses[:, 1], compose(joined.transforms, local.poses[joined.ancestors[:, 1], 0]))




def test_the_per_pair_refit_weights_each_landmark_by_its_covariance():
    """Stereo landmarks 3-8 m ahead: σ 0.3 m in depth (along x), 1 cm across. Moved by a known
    transform and perturbed by their own covariances, the generalised least-squares refit from a
    start 5 cm / 2° off recovers the turn within 0.2° (median over 50 rows: 0.11°, about what 1 cm
    across at 3-8 m allows); an unweighted fit reads the depth errors as a turn (0.91°). Noise-free
    pairs give the transform exactly."""
    from mrslam_core.fusion.alignment import apply_transform, rigid_transform_2d
    from mrslam_core.fusion.join import gls_pair_transforms

    rng = np.random.default_rng(11)
    m, p = 50, 12
    truth = np.array([1.7, 5.5, 0.3])
    src = np.stack([rng.uniform(3, 8, (m, p)), rng.uniform(-2, 2, (m, p))], -1)
    cov_src = np.broadcast_to(np.diag([0.3**2, 0.01**2]), (m, p, 2, 2)).copy()
    cov_dst = np.zeros((m, p, 2, 2)) + 1e-8 * np.eye(2)
    w = np.ones((m, p))
    start = np.broadcast_to(truth + [0.05, -0.03, np.radians(2)], (m, 3))
    exact = gls_pair_transforms(start, src, apply_transform(truth, src), cov_src, cov_dst, w)
    np.testing.assert_allclose(exact, np.broadcast_to(truth, (m, 3)), atol=1e-9)
    noisy_src = src + np.stack([0.3 * rng.standard_normal((m, p)), 0.01 * rng.standard_normal((m, p))], -1)
    dst = apply_transform(truth, src)
    fit = gls_pair_transforms(start, noisy_src, dst, cov_src, cov_dst, w)
    plain = rigid_transform_2d(noisy_src, dst, w)
    # the turn error at the landmarks' distance, per row
    gls_turn = np.abs(np.degrees(fit[:, 2] - truth[2]))
    plain_turn = np.abs(np.degrees(plain[:, 2] - truth[2]))
    assert np.median(gls_turn) < 0.2 and np.median(plain_turn) > 3 * np.median(gls_turn)
    at_landmarks = np.linalg.norm(apply_transform(fit, src.mean(1, keepdims=True))[:, 0] - dst.mean(1), axis=1)
    assert np.median(at_landmarks) < 0.1
