"""Robot-to-robot sightings through the central mapper (the path MR.CLAM takes), and the MR.CLAM
adapter's sets. Frames: map x east, y north; base_link x forward, y left; bearings counter-clockwise."""

import numpy as np
import pytest

from mrslam_core.datasets.mrclam import MrclamDataset, OdometryIntegrator
from mrslam_core.evaluation.metrics import interpolate_poses
from mrslam_core.pipelines.central import CentralConfig, CentralMapper, MapCheckConfig
from mrslam_core.pipelines.central.ordering import interpolate_odometry
from mrslam_core.pipelines.mrclam import MrclamConfig, observation_sets, odometry_knots, odometry_poses
from mrslam_core.slam.config import FilterConfig
from mrslam_core.slam.filter import MultiRobotFastSLAM, RobotUpdate
from mrslam_core.types import ObservationSet, RobotSighting

S = 1_000_000_000
RB = FilterConfig(num_particles=50, seed=5, observation_model="range_bearing", initial_pose_sigma=(0.3, 0.3, 0.1))
STARTS = (0.0, 0.0, 0.0, 2.0, 1.0, 0.0)


def _cfg(**kw) -> CentralConfig:
    base = dict(robots=("robot1", "robot2"), start_poses=STARTS, filter=RB, relocalize_after=0.0,
                map_check=MapCheckConfig(every=0.0))
    base.update(kw)
    return CentralConfig(**base)


def _sighting(z=(np.hypot(2.0, 1.0), np.arctan2(1.0, 2.0))) -> RobotSighting:
    # robot1 at the origin facing east sees robot2 at (2, 1): range √5, bearing atan2(1, 2)
    return RobotSighting("robot1", "robot2", np.array(z), np.diag([0.05**2, 0.02**2]))


def _empty(robot: str, t: float, sightings=()) -> ObservationSet:
    return ObservationSet(robot, int(t * S), np.zeros((0, 2)), np.zeros((0, 2, 2)), sightings=sightings)


def _still(m: CentralMapper, until: float = 1.0) -> None:
    for k, r in enumerate(m.robots):
        for t in np.arange(0.0, until + 1e-9, 0.1):
            m.add_odometry(r, int(round(t * S)), np.array(STARTS[3 * k:3 * k + 3]))


def test_a_sighting_in_a_set_weights_the_particles_as_the_filter_scores_it():
    m = CentralMapper(_cfg())
    _still(m)
    m.add_observations(_empty("robot1", 0.5, (_sighting(),)))
    m.add_observations(_empty("robot2", 0.5))
    assert [d.robot for d in m.process()] == ["robot1", "robot2"]
    # the same update given to the filter directly (no motion: the odometry stood still)
    ref = MultiRobotFastSLAM(RB, ["robot1", "robot2"], np.reshape(STARTS, (2, 3)))
    ref.step([RobotUpdate("robot1", S // 2, np.zeros(3), None, [_sighting()])])
    ref.step([RobotUpdate("robot2", S // 2, np.zeros(3), None)])
    np.testing.assert_array_equal(m.slam.log_w, ref.log_w)
    np.testing.assert_array_equal(m.slam.poses, ref.poses)
    assert m.slam.resamples == 1  # a 5 cm sighting of particles spread 0.3 m: Neff collapsed
    assert m.counters() == {}


def test_a_team_step_takes_the_sets_of_one_window_in_one_filter_step():
    m = CentralMapper(_cfg(team_step=0.2))
    _still(m)
    m.add_observations(_empty("robot1", 0.25, (_sighting(),)))
    m.add_observations(_empty("robot2", 0.3))
    m.add_observations(_empty("robot1", 0.4))
    assert m.process() == []  # robot2 has not reached the window's end (0.4 s) yet
    m.add_observations(_empty("robot2", 0.4))
    done = m.process()
    # one pose per robot, after the whole window, at its last set
    assert [(d.robot, d.stamp_ns) for d in done] == [("robot1", 4 * S // 10), ("robot2", 4 * S // 10)]
    assert m.slam.steps == 1 and m.slam.resamples == 1
    ref = MultiRobotFastSLAM(RB, ["robot1", "robot2"], np.reshape(STARTS, (2, 3)))
    ref.step([RobotUpdate("robot1", S // 4, np.zeros(3), None, [_sighting()]),
              RobotUpdate("robot2", 3 * S // 10, np.zeros(3)), RobotUpdate("robot1", 4 * S // 10, np.zeros(3)),
              RobotUpdate("robot2", 4 * S // 10, np.zeros(3))])
    np.testing.assert_array_equal(m.slam.poses, ref.poses)
    np.testing.assert_array_equal(m.slam.log_w, ref.log_w)
    assert [len(t) for t, _ in m.trajectories().values()] == [1, 1]


def test_a_sighting_of_a_robot_the_filter_does_not_hold_is_counted_not_scored():
    m = CentralMapper(_cfg(unknown_start=("robot2",)))
    _still(m)
    m.add_observations(_empty("robot1", 0.5, (_sighting(),)))
    m.process(flush=True)
    assert m.drops["unmapped_sighting"] == 1
    np.testing.assert_array_equal(m.slam.log_w, np.full(RB.num_particles, -np.log(RB.num_particles)))


def test_a_queued_set_keeps_its_sightings_through_a_checkpoint(tmp_path):
    m = CentralMapper(_cfg())
    _still(m)
    m.add_observations(_empty("robot1", 0.5, (_sighting(), _sighting((2.0, 0.5)))))
    assert m.process() == [] and m.queued == 1  # waits for robot2
    resumed = CentralMapper.resume(_cfg(), m.save(tmp_path / "c.npz"))
    (queued,) = [o for *_, o in resumed.ordering._queue]
    assert [s.target for s in queued.sightings] == ["robot2", "robot2"]
    np.testing.assert_array_equal(queued.sightings[1].z, [2.0, 0.5])
    for mapper in (m, resumed):
        mapper.add_observations(_empty("robot2", 0.5))
        mapper.process()
    np.testing.assert_array_equal(m.slam.log_w, resumed.slam.log_w)
    np.testing.assert_array_equal(m.slam.poses, resumed.slam.poses)


def test_a_set_refuses_a_sighting_taken_by_another_robot():
    with pytest.raises(ValueError, match="a sighting by 'robot1' in a set of 'robot2'"):
        _empty("robot2", 0.5, (_sighting(),))


def test_stereo_only_corrections_must_be_off_for_range_bearing_observations():
    with pytest.raises(ValueError, match="relocalize_after and map_check.every"):
        CentralMapper(_cfg(relocalize_after=5.0))
    with pytest.raises(ValueError, match="relocalize_after and map_check.every"):
        CentralMapper(_cfg(map_check=MapCheckConfig()))
    CentralMapper(_cfg())  # both off


def test_odometry_interpolation_is_linear_and_turns_the_short_way_across_pi():
    t = np.array([0, 1, 3]) * S
    poses = np.array([[0.0, 0.0, 3.0], [1.0, 2.0, -3.0], [3.0, 2.0, -2.0]])  # 3 -> -3 rad: +0.283 rad
    buf = list(zip(t.tolist(), poses))
    for q in (0, S // 4, S, 2 * S, 3 * S, 4 * S):
        want = interpolate_poses(np.array([float(q)]), t.astype(float), poses)[0]
        np.testing.assert_allclose(interpolate_odometry(buf, q), want, atol=1e-12)
    np.testing.assert_allclose(interpolate_odometry(buf, S // 4), [0.25, 0.5, 3.0 + (2 * np.pi - 6.0) / 4], atol=1e-12)


def test_the_mrclam_sets_are_its_frames_and_every_window_end(mrclam6):
    ds = MrclamDataset(mrclam6)
    cfg = MrclamConfig()
    t0, _ = ds.time_span()
    sets = observation_sets(ds, cfg, "robot3", cfg.robots, t0, t0 + 60.0)
    stamps = np.array([o.stamp_ns for o in sets])
    assert (np.diff(stamps) > 0).all()
    ends = np.arange(1, 301) * (S // 5)
    assert np.isin(ends, stamps).all()  # every robot reaches each window's end
    m = ds.robots[3].measurements
    m = m[(m[:, 0] > t0) & (m[:, 0] <= t0 + 60.0)]
    frames = np.unique(m[:, 0])
    assert len(sets) == len(np.union1d(np.round((frames - t0) * 1e9).astype(np.int64), ends))
    readings = {(t, s) for t, s in m[:, :2]}  # one reading per subject and frame
    got = sum(len(o) + len(o.sightings) for o in sets)
    assert got == len(readings)
    assert sum(len(o.sightings) for o in sets) == len({(t, s) for t, s in readings if s <= 5})
    assert all(s.target != "robot3" and s.observer == "robot3" for o in sets for s in o.sightings)
    assert all(o.descriptors.shape == (len(o), 21) for o in sets if len(o))
    solo = observation_sets(ds, cfg, "robot3", ("robot3",), t0, t0 + 60.0)
    assert not any(o.sightings for o in solo) and len(solo) == len(sets)


def test_the_fed_odometry_interpolates_to_the_dead_reckoning(mrclam6):
    ds = MrclamDataset(mrclam6)
    t0, _ = ds.time_span()
    odo = OdometryIntegrator(ds.robots[2].odometry, 0.25)  # robot 2's log has a 1.03 s hole
    knots = odometry_knots(odo, t0)
    fed = [odometry_poses(odo, t0, knots, -1 if k == 1 else (k - 1) * S // 5, k * S // 5) for k in range(1, 301)]
    stamps = np.concatenate([s for s, _ in fed])
    assert stamps[0] == 0 and (np.diff(stamps) > 0).all() and np.isin(np.arange(1, 301) * S // 5, stamps).all()
    buf = list(zip(stamps.tolist(), np.concatenate([p for _, p in fed])))
    q = np.random.default_rng(0).integers(0, 60 * S, 500)
    got = np.array([interpolate_odometry(buf, int(t)) for t in q])
    want = odo.pose(t0 + q * 1e-9)  # absolute times ~1.2e9 s resolve 0.24 µs: 1e-7 m at 0.4 m/s
    np.testing.assert_allclose(got[:, :2], want[:, :2], atol=1e-7)
    np.testing.assert_allclose(np.cos(got[:, 2] - want[:, 2]), 1.0, atol=1e-12)
