"""Merging a robot from a mutual sighting (rendezvous): exact geometry and the join.

Frames: body x forward, y left; bearing = atan2(Δy, Δx) − θ; a transform (tx, ty, θ) moves the
local frame into the common frame, p_common = R·p_local + t.
"""

import numpy as np
from scipy.stats import chi2

from mrslam_core.fusion.acceptance import evidence_distance
from mrslam_core.fusion.config import FusionConfig
from mrslam_core.fusion.rendezvous import (
    RendezvousGate,
    anchored_transforms,
    join_by_rendezvous,
    join_rendezvous,
    relative_pose,
    rendezvous_transform,
    sighting_transform,
    transform_spread,
)
from mrslam_core.geometry.se2 import between, compose, inverse, wrap_angle
from mrslam_core.slam.config import FilterConfig
from mrslam_core.slam.filter import MultiRobotFastSLAM

COV = np.diag([0.25**2, 0.04**2])


def range_bearing(frm: np.ndarray, to: np.ndarray) -> np.ndarray:
    d = to[:2] - frm[:2]
    return np.array([np.hypot(*d), wrap_angle(np.arctan2(d[1], d[0]) - frm[2])])


def test_mutual_sighting_gives_the_relative_pose_exactly():
    x_i, x_j = np.array([1.0, 2.0, 2.5]), np.array([-0.5, 4.0, -1.2])  # headings beyond ±π/2
    rel, cov = relative_pose(range_bearing(x_i, x_j), range_bearing(x_j, x_i), COV, COV)
    np.testing.assert_allclose(rel, between(x_i, x_j), atol=1e-12)
    # heading variance = both bearings' variances; range variance halves with two readings
    assert cov[2, 2] == np.float64(2 * 0.04**2)
    r = np.hypot(*(x_j[:2] - x_i[:2]))
    np.testing.assert_allclose(np.linalg.eigvalsh(cov[:2, :2]).max(), max(0.25**2 / 2, r**2 * 0.04**2), rtol=1e-9)


def test_rendezvous_transform_recovers_the_local_frame():
    t_true = np.array([3.0, -1.0, 2.2])  # local frame -> common frame
    x_i, x_j = np.array([2.0, 1.0, 0.3]), np.array([4.0, 2.5, -2.0])  # common frame
    x_i_local = compose(inverse(t_true), x_i)
    rel, rel_cov = relative_pose(range_bearing(x_i, x_j), range_bearing(x_j, x_i), COV, COV)
    rv = rendezvous_transform(x_j, np.diag([0.01, 0.01, 0.001]), x_i_local, rel, rel_cov)
    np.testing.assert_allclose(rv.transform, t_true, atol=1e-12)
    # its covariance holds j's pose covariance and the sightings' heading variance at least
    assert rv.transform_cov[2, 2] >= 0.001 + 2 * 0.04**2 - 1e-12
    assert np.all(np.linalg.eigvalsh(rv.transform_cov) > 0)


def test_join_by_rendezvous_places_the_robot_and_fuses_the_landmark_it_shares():
    t_true = np.array([-2.0, 3.0, -0.7])
    x_j, x_i = np.array([1.0, 1.0, 0.4]), np.array([3.0, 2.0, 2.9])
    central = MultiRobotFastSLAM(FilterConfig(num_particles=400, seed=1), ["a"], x_j[None])
    central.poses[:, 0] = x_j  # exactly known
    local = MultiRobotFastSLAM(FilterConfig(num_particles=10, seed=2), ["b"], np.zeros((1, 3)))
    local.poses[:, 0] = compose(inverse(t_true), x_i)
    eye = np.eye(3, dtype=np.float32)
    # a landmark both mapped (descriptor e0), and one only the local robot mapped (e2)
    lm_common = np.array([5.0, 5.0, 0.0])
    central.insert_landmarks(np.broadcast_to(lm_common, (400, 1, 3)).copy(),
                             np.broadcast_to(np.eye(3) * 0.01, (400, 1, 3, 3)).copy(), np.ones((400, 1), bool), eye[:1])
    lm_local = np.stack([compose(inverse(t_true), np.r_[lm_common[:2], 0.0]), compose(inverse(t_true), np.array([0.0, 6.0, 0.0]))])
    lm_local[:, 2] = 0.0
    local.insert_landmarks(np.broadcast_to(lm_local, (10, 2, 3)).copy(),
                           np.broadcast_to(np.eye(3) * 0.01, (10, 2, 3, 3)).copy(), np.ones((10, 2), bool), eye[[0, 2]])
    cfg = FusionConfig(inlier_distance=0.5, source_outliers="drop")
    rv, res = join_by_rendezvous(central, local, "b", "a", range_bearing(x_i, x_j), range_bearing(x_j, x_i), COV, COV, cfg)
    np.testing.assert_allclose(rv.transform, t_true, atol=1e-9)
    assert central.robots == ["a", "b"] and res.fused == 1 and res.added == 1
    # each particle drew its own transform from N(T, Cov T): the robot is spread around the truth
    p = central.poses[:, 1]
    assert np.linalg.norm(p[:, :2].mean(0) - x_i[:2]) < 0.05
    assert abs(wrap_angle(np.arctan2(np.sin(p[:, 2]).mean(), np.cos(p[:, 2]).mean()) - x_i[2])) < 0.02
    assert 0.02 < np.degrees(p[:, 2].std()) < 10
    # the local-only landmark arrives near its true common-frame position (spread by the transforms)
    mean, ex = central.landmarks.gather(np.arange(400)[:, None], res.slot_map[1:2][None], ("mean", "exists"))
    assert ex.all() and np.linalg.norm(mean[:, 0, :2].mean(0) - np.array([0.0, 6.0])) < 0.1


def _gate_world():
    """Robot j ('a') of the central filter at a known pose; robot i ('b') with its own frame."""
    t_true = np.array([1.5, -2.0, 0.9])  # local frame of b -> common frame
    x_j, x_i, x_k = np.array([0.0, 0.0, 0.3]), np.array([2.0, 1.5, -2.4]), np.array([0.5, 2.5, 1.0])
    central = MultiRobotFastSLAM(FilterConfig(num_particles=200, seed=3), ["a"], x_j[None])
    central.poses[:, 0] = x_j
    local = MultiRobotFastSLAM(FilterConfig(num_particles=10, seed=4), ["b"], np.zeros((1, 3)))
    local.poses[:, 0] = compose(inverse(t_true), x_i)
    return t_true, x_i, x_j, x_k, central, local


def _sighting(central, local, z_ij, z_ji, rng):
    noise = np.sqrt(np.diag(COV))
    return sighting_transform(central, local, "a", z_ij + rng.standard_normal(2) * noise,
                              z_ji + rng.standard_normal(2) * noise, COV, COV)


def test_a_single_mutual_sighting_is_held_and_a_consistent_second_one_merges():
    t_true, x_i, x_j, _, central, local = _gate_world()
    rng = np.random.default_rng(5)
    cfg = FusionConfig(inlier_distance=0.5, source_outliers="drop", evidence_window=10.0)
    gate = RendezvousGate.from_config(cfg)
    z_ij, z_ji = range_bearing(x_i, x_j), range_bearing(x_j, x_i)
    first = _sighting(central, local, z_ij, z_ji, rng)
    assert gate.offer_sighting("b", 20.0, first) is None and "held" in gate.log["b"][-1]
    second = _sighting(central, local, z_ij, z_ji, rng)
    assert evidence_distance(first.evidence(), second.evidence()) < gate.threshold
    ok = gate.offer_sighting("b", 20.4, second)
    assert ok is second and "b" not in gate.held
    res = join_rendezvous(central, local, "b", ok, cfg)
    assert central.robots == ["a", "b"] and res.robot == "b"
    p = central.poses[:, 1]
    assert np.linalg.norm(p[:, :2].mean(0) - x_i[:2]) < 0.3
    np.testing.assert_allclose(ok.transform[:2], t_true[:2], atol=0.5)


def test_a_corrupted_sighting_does_not_merge_and_says_why():
    """A misread barcode (i's reading is of robot k, not j) disagrees with a correct sighting; a
    wrong range (1.5 m too long) disagrees with the other robot's range and is refused outright;
    a later correct sighting confirms the first."""
    _, x_i, x_j, x_k, central, local = _gate_world()
    rng = np.random.default_rng(6)
    gate = RendezvousGate.from_config(FusionConfig(evidence_window=10.0, join_confidence=0.99))
    assert gate.threshold == np.float64(chi2.ppf(0.99, 3))
    z_ij, z_ji = range_bearing(x_i, x_j), range_bearing(x_j, x_i)
    good = _sighting(central, local, z_ij, z_ji, rng)
    misread = _sighting(central, local, range_bearing(x_i, x_k), z_ji, rng)
    too_far = _sighting(central, local, z_ij + np.array([1.5, 0.0]), z_ji, rng)
    assert gate.offer_sighting("b", 30.0, good) is None
    assert evidence_distance(good.evidence(), misread.evidence()) > gate.threshold
    assert gate.offer_sighting("b", 30.2, misread) is None
    assert "sighting with a disagrees with held evidence" in gate.log["b"][-1] and "not joined" in gate.log["b"][-1]
    assert too_far.range_nis > gate.range_threshold > good.range_nis
    assert gate.offer_sighting("b", 30.4, too_far) is None
    assert "ranges disagree" in gate.log["b"][-1]
    assert [h[0] for h in gate.held["b"]] == [30.0, 30.2]  # the refused one is not even held
    assert len(central.robots) == 1  # nothing merged
    again = _sighting(central, local, z_ij, z_ji, rng)
    assert gate.offer_sighting("b", 31.0, again) is again


def test_a_corrupted_first_sighting_is_outvoted_and_old_sightings_expire():
    _, x_i, x_j, x_k, central, local = _gate_world()
    rng = np.random.default_rng(7)
    gate = RendezvousGate.from_config(FusionConfig(evidence_window=5.0))
    z_ij, z_ji = range_bearing(x_i, x_j), range_bearing(x_j, x_i)
    assert gate.offer_sighting("b", 10.0, _sighting(central, local, range_bearing(x_i, x_k), z_ji, rng)) is None
    assert gate.offer_sighting("b", 10.2, _sighting(central, local, z_ij, z_ji, rng)) is None
    late = _sighting(central, local, z_ij, z_ji, rng)
    assert gate.offer_sighting("b", 16.0, late) is None  # the correct one at 10.2 s is 5.8 s old
    assert "held" in gate.log["b"][-1]
    confirm = _sighting(central, local, z_ij, z_ji, rng)
    assert gate.offer_sighting("b", 16.2, confirm) is confirm
    # no window: one sighting is trusted as it is
    single = RendezvousGate.from_config(FusionConfig(evidence_window=None))
    assert single.offer_sighting("b", 1.0, confirm) is confirm


def test_anchored_transforms_put_every_particle_at_its_own_sighting_pose():
    """Each particle's robot i lands at x_j[m] ⊕ rel⁻¹ whatever its local pose; with the sighting's
    noise drawn per particle, the joined poses spread as J·rel_cov·Jᵀ around it."""
    rng = np.random.default_rng(11)
    rel = np.array([2.0, 0.5, 2.8])
    x_j = np.array([1.0, -1.0, 0.4]) + rng.normal(0, [0.05, 0.05, 0.02], (6, 3))
    x_loc = np.array([0.3, 0.2, -0.5]) + rng.normal(0, [0.1, 0.1, 0.2], (6, 3))
    t = anchored_transforms(x_j, x_loc, rel, np.eye(3) * 1e-30, rng)
    np.testing.assert_allclose(compose(t, x_loc), compose(x_j, inverse(rel)), atol=1e-5)  # 1e-12 jitter
    # the transforms differ by the local poses' spread (0.2 rad in heading here)
    assert np.std(t[:, 2]) > 0.05
    # sighting noise: 40000 draws for one particle pair, covariance of x_i = x_j ⊕ rel⁻¹
    rel_cov = np.array([[0.04, 0.01, 0.0], [0.01, 0.02, 0.003], [0.0, 0.003, 0.0032]])
    n = 40000
    t = anchored_transforms(np.broadcast_to(x_j[0], (n, 3)), np.broadcast_to(x_loc[0], (n, 3)), rel, rel_cov, rng)
    xi = compose(t, x_loc[0])
    jac = np.zeros((3, 3))
    for c in range(3):
        d = np.zeros(3)
        d[c] = 1e-6
        diff = compose(x_j[0], inverse(rel + d)) - compose(x_j[0], inverse(rel - d))
        diff[2] = wrap_angle(diff[2])
        jac[:, c] = diff / 2e-6
    expect = jac @ rel_cov @ jac.T
    np.testing.assert_allclose(transform_spread(xi), expect, rtol=0.05, atol=2e-4)


def test_transform_spread_wraps_the_heading_and_uses_the_weights():
    rng = np.random.default_rng(12)
    cov = np.diag([0.01, 0.04, 0.0025])
    t = rng.multivariate_normal([1.0, 2.0, np.pi - 0.01], cov, 50000)
    t[:, 2] = wrap_angle(t[:, 2])  # half of them near -π
    np.testing.assert_allclose(transform_spread(t), cov, rtol=0.03, atol=1e-4)
    # weights: all mass on two transforms 0.2 rad apart across ±π
    two = np.array([[0.0, 0.0, np.pi - 0.1], [2.0, 0.0, -np.pi + 0.1], [50.0, 50.0, 0.0]])
    c = transform_spread(two, np.log(np.array([0.5, 0.5, 1e-300])))
    np.testing.assert_allclose(c[[0, 2], [0, 2]], [1.0, 0.01], rtol=1e-9)


def test_an_anchored_rendezvous_join_keeps_the_local_uncertainty_in_the_map_not_the_pose():
    """Local particles that disagree about their heading by 0.2 rad (sd): joined without anchoring
    the robot inherits that spread around the sighting; anchored, it is spread only by the
    sightings (≈ √2·0.04 rad) while each particle keeps its landmark exactly where its own local
    particle saw it relative to the robot."""
    t_true = np.array([-2.0, 3.0, -0.7])
    x_j, x_i = np.array([1.0, 1.0, 0.4]), np.array([3.0, 2.0, 2.9])
    lm = np.array([0.0, 6.0, 0.0])
    spreads = {}
    for anchor in (False, True):
        central = MultiRobotFastSLAM(FilterConfig(num_particles=400, seed=1), ["a"], x_j[None])
        central.poses[:, 0] = x_j
        local = MultiRobotFastSLAM(FilterConfig(num_particles=400, seed=2), ["b"], np.zeros((1, 3)))
        local.poses[:, 0] = compose(inverse(t_true), x_i)
        local.poses[:, 0, 2] += np.random.default_rng(3).normal(0, 0.2, 400)
        lm_l = compose(inverse(t_true), lm)
        lm_l[2] = 0.0
        eye = np.eye(3, dtype=np.float32)
        local.insert_landmarks(np.broadcast_to(lm_l, (400, 1, 3)).copy(),
                               np.broadcast_to(np.eye(3) * 0.01, (400, 1, 3, 3)).copy(), np.ones((400, 1), bool), eye[2:3])
        cfg = FusionConfig(rendezvous_anchor=anchor, transform_uncertainty="proposal")
        rv, res = join_by_rendezvous(central, local, "b", "a", range_bearing(x_i, x_j), range_bearing(x_j, x_i), COV, COV, cfg)
        p = central.poses[:, 1]
        spreads[anchor] = np.std(wrap_angle(p[:, 2] - x_i[2]))
        if anchor:
            assert abs(np.mean(wrap_angle(p[:, 2] - x_i[2]))) < 0.01
            mean = central.landmarks.gather(np.arange(400)[:, None], res.slot_map[:1][None], ("mean",))[0][:, 0]
            anc_l = res.ancestors[:, 1]
            # the landmark relative to the joined robot, per particle, as its local ancestor had it
            rel_now = compose(inverse(p), np.column_stack([mean[:, :2], np.zeros(400)]))[:, :2]
            rel_loc = compose(inverse(local.poses[anc_l, 0]), np.r_[lm_l[:2], 0.0])[:, :2]
            np.testing.assert_allclose(rel_now, rel_loc, atol=1e-5)
            # nothing of Cov T added on top of the anchored draw (it is the sampled transform)
            np.testing.assert_allclose(central.pending_cov.get(1, np.zeros((3, 3))), 0.0)
            assert np.isfinite(transform_spread(res.transforms)).all()
    assert spreads[False] > 0.18
    assert 0.04 < spreads[True] < 0.08
