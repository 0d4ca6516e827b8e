"""The multi-robot filter: seeded runs on the synthetic stereo world with error bounds, the
shared map, resampling without aliasing, and bad input that never corrupts the state."""

from dataclasses import replace

import numpy as np
import pytest

from mrslam_core.datasets.synthetic import SyntheticWorld, SyntheticWorldConfig
from mrslam_core.slam.config import AssociationConfig, ExistenceConfig, FilterConfig, MotionConfig, RelocalizationConfig
from mrslam_core.slam.filter import FilterInputError, MultiRobotFastSLAM, RobotUpdate
from mrslam_core.types import ObservationSet, RobotSighting

WORLD = SyntheticWorldConfig(seed=1, sigma_d=1.0, sigma_r=10.0, sigma_c=10.0)


def run(world_cfg: SyntheticWorldConfig, filter_cfg: FilterConfig, steps: int):
    world = SyntheticWorld(world_cfg)
    slam = MultiRobotFastSLAM(filter_cfg, world.robots, world.start_poses())
    est_err, odo_err = [], []
    for _, true, odom, updates in world.run(steps):
        slam.step(updates)
        est_err.append(np.linalg.norm(slam.estimate().poses[:, :2] - true[:, :2], axis=1))
        odo_err.append(np.linalg.norm(odom[:, :2] - true[:, :2], axis=1))
    rmse = lambda e: np.sqrt(np.mean(np.square(e), axis=0))  # noqa: E731
    return slam, world, rmse(est_err), rmse(odo_err)


@pytest.mark.parametrize("proposal", ["fastslam1", "fastslam2"])
def test_three_robots_beat_odometry_and_map_is_accurate(proposal):
    slam, world, est, odo = run(WORLD, FilterConfig(num_particles=100, seed=2, proposal=proposal), 150)
    assert np.all(est < 0.5 * odo), (est, odo)
    assert np.all(est < 0.25), est
    slots, mean, _, _, counts = slam.best_map()
    # landmarks seen at least 3 times sit within 0.3 m of a true landmark
    d = np.linalg.norm(mean[counts >= 3][:, None] - world.landmarks[None], axis=2).min(axis=1)
    assert np.median(d) < 0.15 and np.mean(d < 0.3) > 0.9


def test_robots_share_one_map():
    # robot2 follows robot1's loop later: it must re-observe landmarks robot1 created
    slam, world, _, _ = run(replace(WORLD, num_robots=2), FilterConfig(num_particles=50, seed=3), 60)
    best = slam.best_particle()
    assert slam.landmarks.size > 0
    counts = slam.landmarks.gather(np.full(slam.landmarks.size, best), np.arange(slam.landmarks.size), ("count",))[0]
    assert (counts >= 5).sum() > 50  # many landmarks carry repeated (team) observations


def test_resampling_copies_without_aliasing():
    slam, _, _, _ = run(WORLD, FilterConfig(num_particles=30, seed=4, resample_threshold=1.0), 5)
    assert slam.resamples > 0
    store = slam.landmarks
    slots = np.arange(store.size)
    before = store.gather(np.arange(30)[:, None], slots[None], ("mean",))[0].copy()
    # write into particle 0 only: no other particle may change
    store.write(np.zeros(store.size, int), slots, mean=np.full((store.size, 3), 123.0))
    after = store.gather(np.arange(30)[:, None], slots[None], ("mean",))[0]
    assert np.all(after[0] == 123.0)
    np.testing.assert_array_equal(after[1:], before[1:])


def _obs(robot, stamp, z, cov=None, desc=None):
    z = np.asarray(z, float)
    cov = np.broadcast_to(np.eye(3) * 0.01, (len(z), 3, 3)) if cov is None else cov
    desc = np.ones((len(z), 4), np.float32) / 2 if desc is None else desc
    return ObservationSet(robot, stamp, z, cov, desc)


def _state(slam):
    return (slam.poses.copy(), slam.log_w.copy(), slam.landmarks.size, slam.landmarks.table.copy())


def test_every_landmark_records_the_robot_and_the_stamp_that_made_it():
    slam = MultiRobotFastSLAM(FilterConfig(num_particles=5, seed=0), ["a", "b"], np.zeros((2, 3)))
    d = np.eye(4, dtype=np.float32)
    slam.step([RobotUpdate("a", 10, np.zeros(3), _obs("a", 10, [[2.0, 0.0, 1.0]], desc=d[:1]))])
    slam.step([RobotUpdate("b", 20, np.zeros(3), _obs("b", 20, [[-3.0, 0.0, 1.0], [0.0, 4.0, 1.0]], desc=d[1:3]))])
    store = slam.landmarks
    assert store.size == 3
    assert store.maker[:3].tolist() == [0, 1, 1] and store.born[:3].tolist() == [10, 20, 20]


def test_bad_input_is_dropped_and_counted_without_corrupting_state():
    slam = MultiRobotFastSLAM(FilterConfig(num_particles=10), ["a", "b"], np.zeros((2, 3)))
    slam.step([RobotUpdate("a", 1, np.zeros(3), _obs("a", 1, [[2.0, 0.0, 1.0]]))])
    snap = _state(slam)
    slam.step([RobotUpdate("ghost", 2, np.zeros(3))])  # unknown robot
    slam.step([RobotUpdate("a", 2, np.array([np.nan, 0, 0]))])  # NaN odometry
    slam.step([RobotUpdate("a", 1, np.zeros(3))])  # stamp not newer
    slam.step([RobotUpdate("a", 1, np.zeros(3))])  # duplicate stamp
    for got, want in zip(_state(slam), snap):
        np.testing.assert_array_equal(got, want)
    assert slam.dropped == {"unknown_robot": 1, "bad_odometry": 1, "stale_stamp": 2}
    # rows with NaN/inf or a non-positive-definite covariance are dropped, the rest is used
    bad_cov = np.stack([np.eye(3) * 0.01, -np.eye(3), np.eye(3) * 0.01])
    slam.step([RobotUpdate("a", 3, np.zeros(3), _obs("a", 3, [[2.0, 0, 1], [1, 1, 1], [np.inf, 0, 0]], bad_cov))])
    assert slam.dropped["bad_observation"] == 2
    assert np.isfinite(slam.poses).all() and np.isfinite(slam.log_w).all()
    # an empty observation set is a pure motion update
    slam.step([RobotUpdate("b", 4, np.array([0.1, 0, 0]), _obs("b", 4, np.zeros((0, 3))))])
    # a wrong measurement dimension is a programming error: a clear exception
    with pytest.raises(FilterInputError, match="dimension"):
        slam.step([RobotUpdate("a", 5, np.zeros(3), ObservationSet("a", 5, np.zeros((1, 2)), np.eye(2)[None]))])


def test_robot_sightings_pull_particles_together():
    cfg = FilterConfig(num_particles=200, seed=5, initial_pose_sigma=(0.3, 0.3, 0.0),
                       observation_model="range_bearing")
    slam = MultiRobotFastSLAM(cfg, ["a", "b"], np.array([[0.0, 0, 0], [2.0, 0, 0]]))
    cov = np.diag([0.01, 0.001])
    for t in range(1, 6):
        slam.step([RobotUpdate("a", t, np.zeros(3), sightings=[RobotSighting("a", "b", np.array([2.0, 0.0]), cov)])])
    rel = slam.poses[:, 1, :2] - slam.poses[:, 0, :2]
    w = np.exp(slam.log_w)
    assert np.linalg.norm(w @ rel - [2.0, 0.0]) < 0.1
    slam.step([RobotUpdate("a", 9, np.zeros(3), sightings=[RobotSighting("a", "zz", np.array([1.0, 0]), cov)])])
    assert slam.dropped["bad_sighting"] == 1


def test_hungarian_mode_runs_and_beats_odometry():
    cfg = FilterConfig(num_particles=40, seed=6, association=AssociationConfig(mode="hungarian"))
    _, _, est, odo = run(WORLD, cfg, 80)
    assert np.all(est < odo)


def test_config_validation():
    with pytest.raises(ValueError):
        FilterConfig(num_particles=0)
    with pytest.raises(FilterInputError):
        MultiRobotFastSLAM(FilterConfig(), ["a", "a"], np.zeros((2, 3)))



@pytest.mark.parametrize("make, field", [
    (lambda: FilterConfig(association=AssociationConfig(outlier_gate=11.34)), "association.outlier_gate"),
    (lambda: FilterConfig(relocalization=RelocalizationConfig(enabled=True)), "relocalization.enabled"),
    (lambda: FilterConfig(relocalization=RelocalizationConfig(iterations=3)), "relocalization.iterations"),
    (lambda: FilterConfig(existence=ExistenceConfig(max_range=8.0)), "existence.max_range"),
    (lambda: AssociationConfig(mode="hungarian", track_gate=30.0), "track_gate"),
    (lambda: AssociationConfig(mode="hungarian", geometry_weight=0.0), "geometry_weight"),
    (lambda: AssociationConfig(candidate_search="descriptor", search_radius_m=2.0), "search_radius_m"),
    (lambda: AssociationConfig(outlier_rounds=5), "outlier_rounds"),
    (lambda: AssociationConfig(track_memory=3), "track_memory"),
])
def test_a_setting_that_does_nothing_under_the_chosen_mode_is_an_error(make, field):
    with pytest.raises(ValueError, match=f"^{field.replace('.', '[.]')} = .* does nothing"):
        make()
    # the same settings where they act are accepted
    FilterConfig(proposal="fastslam2", association=AssociationConfig(outlier_gate=11.34, outlier_rounds=5,
                                                                     track_gate=30.0, track_memory=3),
                 relocalization=RelocalizationConfig(enabled=True, iterations=3),
                 existence=ExistenceConfig(enabled=True, max_range=8.0))
    AssociationConfig(mode="hungarian", candidate_search="descriptor", max_candidates=4)

def test_spurious_landmarks_disappear_with_the_existence_counter():
    from mrslam_core.slam.config import ExistenceConfig

    cfg = FilterConfig(
        num_particles=20, seed=7,
        existence=ExistenceConfig(enabled=True, fov_rad=1.2, min_range=0.3, max_range=6.0, max_score=3),
    )
    real = np.array([[3.0, 0.0, 1.0], [3.0, 1.0, 1.0]])
    slam = MultiRobotFastSLAM(cfg, ["a"], np.zeros((1, 3)))
    desc = np.eye(3, 8, dtype=np.float32)
    # one frame with a spurious third point, then 10 frames of only the two real points
    slam.step([RobotUpdate("a", 1, np.zeros(3), _obs("a", 1, np.vstack([real, [[4.0, -1.0, 1.0]]]), desc=desc))])
    assert slam.landmarks.size == 3
    for t in range(2, 12):
        slam.step([RobotUpdate("a", t, np.zeros(3), _obs("a", t, real, desc=desc[:2]))])
    _, mean, _, _, _ = slam.best_map()
    assert len(mean) == 2  # the spurious landmark was in view, unseen, and removed
    np.testing.assert_allclose(np.sort(mean[:, 1]), [0.0, 1.0], atol=0.05)
    assert slam.removed_landmarks == 20  # once in each particle


def test_delayed_initialisation_keeps_candidates_out_of_the_weights():
    cfg = FilterConfig(num_particles=10, seed=8, association=AssociationConfig(min_observations=3))
    slam = MultiRobotFastSLAM(cfg, ["a"], np.zeros((1, 3)))
    pt = np.array([[3.0, 0.5, 1.0]])
    for t in range(1, 5):
        slam.step([RobotUpdate("a", t, np.zeros(3), _obs("a", t, pt))])
    (count,) = slam.landmarks.gather(np.zeros(1, int), np.zeros(1, int), ("count",))
    assert slam.landmarks.size == 1 and count[0] == 4  # one slot, promoted after 3 observations


def test_candidate_is_promoted_after_exactly_nz_min_sightings():
    cfg = FilterConfig(num_particles=5, seed=9, association=AssociationConfig(min_observations=3))
    slam = MultiRobotFastSLAM(cfg, ["a"], np.zeros((1, 3)))
    pt = np.array([[3.0, 0.5, 1.0]])
    cov = np.eye(3) * 0.01
    log_p0 = -0.5 * (cfg.association.mahalanobis_gate + 3 * np.log(2 * np.pi) + np.log(np.linalg.det(cov)))
    increments = []
    for t in range(1, 6):
        before = slam.score.copy()
        slam.step([RobotUpdate("a", t, np.zeros(3), _obs("a", t, pt))])
        increments.append(slam.score - before)
    # sightings 1-3: new landmark, then a candidate: the weight factor is p0 in every particle
    for inc in increments[:3]:
        np.testing.assert_allclose(inc, log_p0)
    # from sighting 4 on it is a landmark and the observation likelihood weights the particle
    assert not np.allclose(increments[3], log_p0)
    assert np.all(increments[3] > log_p0)  # a perfect re-observation beats "new"


def test_hungarian_leaves_fewer_duplicates_than_ml_on_the_ambiguous_world():
    from mrslam_core.experiments.association import ambiguous_run

    dup = {mode: sum(ambiguous_run(mode, seed, 30)["duplicated_fraction"] for seed in (5, 7)) for mode in ("ml", "hungarian")}
    assert dup["hungarian"] < dup["ml"], dup


# ---------------------------------------------------------------- lost robots (MR.CLAM robot 4)
_LANDMARKS = np.array([[3.0, 1.0], [2.0, -2.0], [-1.0, 3.0]])  # map frame [m]


def _rb(pose, idx):
    """Exact range-bearing observations of landmarks ``idx`` from ``pose`` (x, y, θ)."""
    d = _LANDMARKS[idx] - pose[:2]
    z = np.column_stack([np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0]) - pose[2]])
    z[:, 1] = (z[:, 1] + np.pi) % (2 * np.pi) - np.pi
    return ObservationSet("a", 0, z, np.broadcast_to(np.diag([0.01, 0.0004]), (len(idx), 2, 2)),
                          np.eye(len(_LANDMARKS), 8, dtype=np.float32)[idx])


def _lost_robot_filter(**kw):
    """One robot that mapped three landmarks at the origin, then had all its particles moved
    1 m and 0.4 rad away from its true pose (as after a long stretch without landmarks)."""
    from mrslam_core.slam.config import MotionConfig, RelocalizationConfig

    cfg = FilterConfig(
        num_particles=50, seed=10, proposal="fastslam2", observation_model="range_bearing",
        motion=MotionConfig(sigma_xy_rw=0.01, sigma_theta_rw=0.01),
        association=AssociationConfig(candidate_search="descriptor", descriptor_trust_gate=1e4),
        relocalization=RelocalizationConfig(enabled=True), **kw,
    )
    slam = MultiRobotFastSLAM(cfg, ["a"], np.zeros((1, 3)))
    for t in range(1, 4):
        slam.step([RobotUpdate("a", t * 10**8, np.zeros(3), _rb(np.zeros(3), [0, 1, 2]))])
    slam.poses[:, 0] += [1.0, -0.5, 0.4]
    slam.drift_cov[0] = np.diag([1.0, 1.0, 0.3])  # what the motion model accumulated meanwhile
    return slam


def test_a_misread_identity_descriptor_starts_no_landmark():
    """Barcodes identify a landmark for certain (descriptor_trust_gate on): a reading of landmark
    0's barcode 20 m from where every particle holds landmark 0 (Mahalanobis ≫ D1) is a misread,
    dropped and counted, not a second landmark 0; the same reading 0.5 m off (beyond D0, within
    D1) is still landmark 0."""
    from mrslam_core.slam.config import MotionConfig

    cfg = FilterConfig(num_particles=20, seed=3, proposal="fastslam2", observation_model="range_bearing",
                       motion=MotionConfig(sigma_xy_rw=0.001, sigma_theta_rw=0.001),
                       association=AssociationConfig(candidate_search="descriptor", descriptor_trust_gate=1e4))
    slam = MultiRobotFastSLAM(cfg, ["a"], np.zeros((1, 3)))
    slam.step([RobotUpdate("a", 10**8, np.zeros(3), _rb(np.zeros(3), [0, 1, 2]))])
    _, before, _, _, _ = slam.best_map()
    far = _rb(np.zeros(3), [0])
    far.z[0, 0] += 20.0
    slam.step([RobotUpdate("a", 2 * 10**8, np.zeros(3), far)])
    slots, after, _, _, _ = slam.best_map()
    assert slots.size == 3 and slam.dropped["misread_descriptor"] == 1
    np.testing.assert_array_equal(after, before)
    near = _rb(np.zeros(3), [0])
    near.z[0, 0] += 0.5
    slam.step([RobotUpdate("a", 3 * 10**8, np.zeros(3), near)])
    slots, after, _, _, _ = slam.best_map()
    assert slots.size == 3 and slam.dropped["misread_descriptor"] == 1
    assert not np.array_equal(after, before)  # landmark 0 updated


def test_lost_robot_is_relocalised_from_two_landmarks():
    slam = _lost_robot_filter()
    _, map_before, _, _, _ = slam.best_map()
    slam.step([RobotUpdate("a", 10**9, np.zeros(3), _rb(np.zeros(3), [0, 1]))])
    assert slam.relocalizations == 1
    est = slam.estimate()
    assert np.hypot(*est.mean[0, :2]) < 0.05 and abs(est.mean[0, 2]) < 0.02, est.mean
    _, map_after, _, _, _ = slam.best_map()
    np.testing.assert_allclose(map_after, map_before, atol=0.06)  # the map was not dragged
    # the drift covariance was shrunk by the observations
    assert np.trace(slam.drift_cov[0]) < 0.05


def test_lost_robot_sets_aside_a_single_landmark_and_keeps_the_map():
    slam = _lost_robot_filter()
    _, map_before, _, _, _ = slam.best_map()
    poses = slam.poses.copy()
    slam.step([RobotUpdate("a", 10**9, np.zeros(3), _rb(np.zeros(3), [2]))])
    assert slam.relocalizations == 0 and slam.dropped["lost_robot_observation"] == 1
    _, map_after, _, _, _ = slam.best_map()
    np.testing.assert_array_equal(map_after, map_before)
    assert np.abs(slam.poses - poses).max() < 0.1  # only motion noise, no pull to the landmark


def test_with_deferred_noise_the_set_aside_observation_leaves_the_noise_pending():
    slam = _lost_robot_filter(defer_motion_noise=True)
    _, map_before, _, _, _ = slam.best_map()
    poses = slam.poses.copy()
    slam.step([RobotUpdate("a", 10**9, np.zeros(3), _rb(np.zeros(3), [2]))])
    assert slam.dropped["lost_robot_observation"] == 1
    np.testing.assert_allclose(slam.poses, poses, atol=1e-12)  # zero odometry, noise not drawn
    assert np.trace(slam.pending_cov[0]) > 0
    _, map_after, _, _, _ = slam.best_map()
    np.testing.assert_array_equal(map_after, map_before)


def test_without_relocalisation_the_lost_robot_stays_lost():
    from mrslam_core.slam.config import RelocalizationConfig

    slam = _lost_robot_filter()
    slam.config = replace(slam.config, relocalization=RelocalizationConfig(enabled=False))
    _, map_before, _, _, _ = slam.best_map()
    slam.step([RobotUpdate("a", 10**9, np.zeros(3), _rb(np.zeros(3), [0, 1]))])
    assert np.hypot(*slam.estimate().mean[0, :2]) > 0.5
    _, map_after, _, _, _ = slam.best_map()
    assert np.abs(map_after - map_before).max() > 0.1  # its observations drag the shared map


def test_deferred_motion_noise_follows_odometry_until_measured():
    from mrslam_core.slam.config import MotionConfig

    cfg = FilterConfig(num_particles=100, seed=11, observation_model="range_bearing", proposal="fastslam2",
                       motion=MotionConfig(sigma_xy_rw=0.05, sigma_theta_rw=0.05), defer_motion_noise=True)
    slam = MultiRobotFastSLAM(cfg, ["a", "b"], np.array([[0.0, 0, 0], [2.0, 0, 0]]))
    for t in range(1, 11):  # robot a drives 1 m straight, nothing measures it
        slam.step([RobotUpdate("a", t * 10**8, np.array([0.1, 0.0, 0.0]))])
    np.testing.assert_allclose(slam.poses[:, 0], np.broadcast_to([1.0, 0.0, 0.0], (100, 3)), atol=1e-12)
    pending = slam.pending_cov[0]
    # heading random walk 0.05²·1 s; carried through the motion it adds lateral (y) variance
    assert pending[2, 2] > 0.0025 and pending[1, 1] > pending[0, 0] + 3e-4
    np.testing.assert_allclose(slam.estimate().cov[0], pending, atol=1e-12)  # reported uncertainty
    # a sighting conditions the pending noise (its range measures x here, its bearing y) and
    # draws nothing: the particles stay identical
    cov = np.diag([0.01, 0.001])
    slam.step([RobotUpdate("b", 11 * 10**8, np.zeros(3), sightings=[RobotSighting("b", "a", np.array([1.0, np.pi]), cov)])])
    after = slam.pending_cov[0]
    assert after[0, 0] < 0.8 * pending[0, 0] and after[1, 1] < 0.5 * pending[1, 1]
    assert np.ptp(slam.poses[:, 0], axis=0).max() < 1e-12


def _means(slam):
    """(M, N, 3) landmark means of every particle."""
    n = slam.landmarks.size
    return slam.landmarks.gather(np.arange(slam.num_particles)[:, None], np.arange(n)[None], ("mean",))[0].copy()


def _look_alike_run(outlier_gate):
    """One robot sees six landmarks, then, 1 s later and 1 mm on (pose σ 0.1 m from the random
    walk, which a robot whose odometry reports no motion would not get), the same six with the
    sixth's point 0.12 m off: a look-alike."""
    from mrslam_core.slam.config import MotionConfig

    cfg = FilterConfig(num_particles=50, seed=5, proposal="fastslam2", resample_threshold=0.0,
                       motion=MotionConfig(sigma_xy_rw=0.1),
                       association=AssociationConfig(outlier_gate=outlier_gate))
    slam = MultiRobotFastSLAM(cfg, ["a"], np.zeros((1, 3)))
    pts = np.array([[2.0, -1.0, 0.5], [2.0, 1.0, 0.5], [3.0, 0.0, 0.3], [2.5, -0.5, 0.8],
                    [2.5, 0.7, 0.2], [3.0, -0.8, 0.4]])
    cov = np.broadcast_to(np.eye(3) * 1e-4, (6, 3, 3))
    desc = np.eye(6, 8, dtype=np.float32)
    slam.step([RobotUpdate("a", 1, np.zeros(3), _obs("a", 1, pts, cov, desc))])
    before = _means(slam)
    seen = pts.copy()
    seen[5, 1] += 0.12
    slam.step([RobotUpdate("a", 10**9 + 1, np.array([1e-3, 0.0, 0.0]), _obs("a", 10**9 + 1, seen, cov, desc))])
    return slam, before


def test_a_look_alike_match_is_left_out_of_the_proposal_and_the_map():
    slam, before = _look_alike_run(11.34)
    # the association gate lets the pair in (the pose is uncertain), the residual at the mode
    # fitted to the five right pairs (σ ≈ 0.006 m) is ~72 > 11.34: an outlier in every particle
    assert slam.outlier_pairs == 50
    assert slam.landmarks.size == 6  # no landmark started from it
    mean = slam.poses[:, 0].mean(axis=0)
    assert np.hypot(*mean[:2]) < 0.004 and abs(mean[2]) < 0.002, mean
    after = _means(slam)
    np.testing.assert_array_equal(after[:, 5], before[:, 5])  # the look-alike did not move its landmark
    assert np.abs(after[:, :5] - before[:, :5]).max() < 0.01

    plain, _ = _look_alike_run(0.0)  # without the gate the six pairs pull the pose −0.12/6 m in y
    assert plain.outlier_pairs == 0
    assert plain.poses[:, 0, 1].mean() < -0.015, plain.poses[:, 0].mean(axis=0)


def test_a_sighting_conditions_the_pending_motion_noise_instead_of_sampling_it():
    """With the motion noise deferred, a sighting of robot b is scored by its marginal
    N(ν; 0, R + H P Hᵀ) under b's pending covariance P and moves b's pose by the EKF gain: the
    particles, identical before, stay identical (nothing is sampled), b's heading, which a
    range and a bearing of its position do not measure, is not moved, and P shrinks by K S Kᵀ."""
    cfg = FilterConfig(num_particles=20, seed=1, initial_pose_sigma=(0.0, 0.0, 0.0), observation_model="range_bearing",
                       motion=MotionConfig(alpha1=0.0, alpha2=0.0, alpha3=0.0, alpha4=0.0, sigma_xy_rw=0.1, sigma_theta_rw=0.1),
                       defer_motion_noise=True, sighting_outlier_probability=0.0)
    slam = MultiRobotFastSLAM(cfg, ["a", "b"], np.array([[0.0, 0, 0], [2.0, 0, 0]]))
    slam.step([RobotUpdate("b", 1, np.zeros(3))])
    slam.step([RobotUpdate("b", 10**9 + 1, np.array([1e-6, 0.0, 0.0]))])  # b moves: 1 s of random walk
    p = slam.pending_cov[1].copy()
    np.testing.assert_allclose(p, np.diag([0.01, 0.01, 0.01]), atol=1e-9)
    b = slam.poses[0, 1].copy()
    z, r = np.array([2.1, 0.05]), np.diag([0.01, 0.001])
    before = slam.log_w.copy()
    slam.step([RobotUpdate("a", 10**9, np.zeros(3), sightings=[RobotSighting("a", "b", z, r)])])
    # the exact linear-Gaussian answer at b's pose (a at the origin, heading 0)
    d = b[:2]
    q = d @ d
    h = np.array([[d[0] / np.sqrt(q), d[1] / np.sqrt(q), 0.0], [-d[1] / q, d[0] / q, 0.0]])
    nu = z - [np.sqrt(q), np.arctan2(d[1], d[0])]
    s = r + h @ p @ h.T
    k = p @ h.T @ np.linalg.inv(s)
    np.testing.assert_allclose(slam.poses[:, 1], np.broadcast_to(b + k @ nu, (20, 3)), atol=1e-12)
    assert slam.poses[0, 1, 2] == b[2]
    np.testing.assert_allclose(slam.pending_cov[1], p - k @ s @ k.T, atol=1e-12)
    ll = -0.5 * (nu @ np.linalg.solve(s, nu) + 2 * np.log(2 * np.pi) + np.log(np.linalg.det(s)))
    assert slam.log_w == pytest.approx(before)  # every particle the same: weights unchanged
    assert slam.score[0] == pytest.approx(ll)
