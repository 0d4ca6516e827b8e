"""Property-based fuzzing of the filter step (hypothesis): arbitrary odometry arrays, observation
sets and sightings with NaN/inf, huge, tiny and empty values, wrong shapes and dimensions,
unknown robots and duplicate or out-of-order stamps.

Properties: a step either succeeds or raises FilterInputError (never another exception); an
update that is dropped, or a step that raises, leaves the filter state exactly as it was; after
any step the particle poses, weights and every held landmark are finite.
"""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from mrslam_core.datasets.synthetic import SyntheticWorld, SyntheticWorldConfig
from mrslam_core.slam.config import ExistenceConfig, FilterConfig
from mrslam_core.slam.filter import MAX_ABS_INPUT, FilterInputError, MultiRobotFastSLAM, RobotUpdate
from mrslam_core.types import ObservationSet, RobotSighting

SETTINGS = settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
ROBOTS = ["robot1", "robot2"]
D = 8  # descriptor length of the warm-up world
WORLD = SyntheticWorldConfig(seed=3, num_robots=2, descriptor_dim=D, num_landmarks=150, width=10.0, height=8.0)
WARMUP = [ups for _, _, _, ups in SyntheticWorld(WORLD).run(3)]  # stamps 0.5 .. 1.5 s

# values that break arithmetic: NaN, ±inf, huge, tiny, zero, and ordinary ones
nasty = st.one_of(
    st.sampled_from([np.nan, np.inf, -np.inf, 1e308, -1e308, 1e30, 1e-300, 0.0, -0.0]),
    st.floats(-20, 20, allow_nan=False, allow_infinity=False),
    st.floats(allow_nan=True, allow_infinity=True, width=64),
)


def farrays(shape):
    return hnp.arrays(np.float64, shape, elements=nasty)


odometry = st.one_of(
    farrays(st.sampled_from([(3,), (2,), (4,), (0,), (), (3, 1), (1, 3)])),
    hnp.arrays(st.sampled_from([np.int64, np.bool_, np.float32]), (3,)),
    st.just([0.1, 0.0, 0.01]),
)


@st.composite
def observation_sets(draw, robot):
    b = draw(st.integers(0, 6))
    dim = draw(st.sampled_from([3, 3, 3, 2]))
    z = draw(st.one_of(farrays((b, dim)), hnp.arrays(np.float64, (b, dim), elements=st.floats(-8, 8))))
    kind = draw(st.sampled_from(["good", "good", "nasty", "scaled"]))
    if kind == "nasty":
        cov = draw(farrays((b, dim, dim)))
    else:
        scale = draw(st.sampled_from([1e-3, 1.0, 1e-300, 1e300])) if kind == "scaled" else 1e-2
        cov = np.broadcast_to(np.eye(dim) * scale, (b, dim, dim)).copy()
    d = draw(st.sampled_from([D, D, D, 0, 3]))
    desc = draw(st.one_of(
        hnp.arrays(np.float32, (b, d), elements=st.floats(-1, 1, width=32)),
        hnp.arrays(np.float32, (b, d), elements=st.sampled_from([np.nan, np.inf, 3e38, 0.0])),
    ))
    return ObservationSet(robot, 0, z, cov, desc, np.arange(b))


@st.composite
def updates(draw):
    robot = draw(st.sampled_from(ROBOTS + ["ghost", ""]))
    stamp = draw(st.one_of(
        st.sampled_from([0, 1, 1_500_000_000, 1_499_999_999, 2_000_000_000, -5, 2**63 - 1]),
        st.integers(-(2**63), 2**63 - 1),
    ))
    obs = draw(st.one_of(st.none(), observation_sets(robot)))
    sightings = draw(st.lists(
        st.builds(RobotSighting, st.just(robot), st.sampled_from(ROBOTS + ["ghost"]),
                  farrays(st.sampled_from([(2,), (3,), (0,)])), farrays(st.sampled_from([(2, 2), (2,), (3, 3)]))),
        max_size=2,
    ))
    return RobotUpdate(robot, stamp, draw(odometry), obs, sightings)


def warm_filter(proposal: str) -> MultiRobotFastSLAM:
    cfg = FilterConfig(num_particles=6, seed=1, proposal=proposal, resample_threshold=0.8,
                       existence=ExistenceConfig(enabled=proposal == "fastslam2"))
    slam = MultiRobotFastSLAM(cfg, ROBOTS, SyntheticWorld(WORLD).start_poses())
    for ups in WARMUP:
        slam.step(ups)
    return slam


def snapshot(slam: MultiRobotFastSLAM) -> dict:
    s = slam.landmarks
    return {
        "poses": slam.poses.copy(), "log_w": slam.log_w.copy(), "score": slam.score.copy(),
        "table": s.table.copy(), "size": s.size, "mean": s.pool_mean.copy(), "cov": s.pool_cov.copy(),
        "exists": s.pool_exists.copy(), "count": s.pool_count.copy(), "desc": s.descriptor.copy(),
        "last_stamp": dict(slam.last_stamp), "rng": slam.rng.bit_generator.state,
    }


def assert_unchanged(before: dict, after: dict) -> None:
    for key, value in before.items():
        if isinstance(value, np.ndarray):
            np.testing.assert_array_equal(after[key], value, err_msg=key)
        else:
            assert after[key] == value, key


def assert_finite(slam: MultiRobotFastSLAM) -> None:
    assert np.isfinite(slam.poses).all()
    assert np.isfinite(slam.log_w).all() and np.isfinite(slam.score).all()
    ex = slam.landmarks.exists_dense()
    m, n = np.nonzero(ex)
    mean, cov = slam.landmarks.gather(m, n, ("mean", "cov"))
    assert np.isfinite(mean).all() and np.isfinite(cov).all()


@pytest.mark.parametrize("proposal", ["fastslam1", "fastslam2"])
@SETTINGS
@given(batch=st.lists(updates(), min_size=1, max_size=3))
def test_step_never_crashes_and_never_corrupts(proposal, batch):
    slam = warm_filter(proposal)
    before = snapshot(slam)
    dropped = sum(slam.dropped.values())
    try:
        result = slam.step(batch)
    except FilterInputError:
        assert_unchanged(before, snapshot(slam))  # a rejected step changes nothing
        return
    assert_finite(slam)
    assert result.dropped.get("total", 0) == sum(slam.dropped.values()) - dropped
    accepted = [u for u in batch if u.robot in ROBOTS]
    if not accepted or slam.last_stamp == before["last_stamp"]:
        # every update was dropped: nothing about the particles may have changed
        assert_unchanged(before, snapshot(slam))


@SETTINGS
@given(odo=odometry, stamp=st.integers(-(2**63), 2**63 - 1), robot=st.sampled_from(ROBOTS + ["ghost"]))
def test_dropped_update_is_counted_and_changes_nothing(odo, stamp, robot):
    slam = warm_filter("fastslam1")
    last = slam.last_stamp["robot1"]
    o = np.asarray(odo, float)
    good_odo = o.shape == (3,) and np.isfinite(o).all() and np.abs(o).max() <= MAX_ABS_INPUT
    will_drop = robot == "ghost" or not good_odo or (stamp <= last)
    before, count = snapshot(slam), sum(slam.dropped.values())
    slam.step([RobotUpdate(robot if robot != "robot2" else "robot1", stamp, odo)])
    if will_drop:
        assert sum(slam.dropped.values()) == count + 1
        assert_unchanged(before, snapshot(slam))
    else:
        assert sum(slam.dropped.values()) == count
        assert_finite(slam)


def test_duplicate_and_out_of_order_stamps_are_dropped():
    slam = warm_filter("fastslam1")
    last = slam.last_stamp["robot1"]
    before = snapshot(slam)
    for stamp in (last, last - 1, 0, -(2**63)):
        slam.step([RobotUpdate("robot1", stamp, np.zeros(3))])
    assert slam.dropped["stale_stamp"] == 4
    assert_unchanged(before, snapshot(slam))


# ----------------------------------------------------------------------------- found by fuzzing
@pytest.mark.parametrize("proposal", ["fastslam1", "fastslam2"])
def test_regressions_found_by_fuzzing(proposal):
    slam = warm_filter(proposal)
    before = snapshot(slam)
    good = WARMUP[0][0].observations
    # a bad second update used to leave the first one (and robot1's motion) applied
    bad_dim = ObservationSet("robot2", 0, np.zeros((1, 2)), np.eye(2)[None] * 0.01, np.zeros((1, D), np.float32))
    bad_desc = ObservationSet("robot2", 0, good.z, good.cov, np.zeros((len(good), 3), np.float32))
    for bad in (bad_dim, bad_desc):
        with pytest.raises(FilterInputError):
            slam.step([RobotUpdate("robot1", 2_000_000_000, np.array([0.1, 0, 0]), good),
                       RobotUpdate("robot2", 2_000_000_000, np.array([0.1, 0, 0]), bad)])
        assert_unchanged(before, snapshot(slam))
    # finite but absurd odometry: OverflowError / LinAlgError / NaN poses before
    for odo in ([1e308, 1e308, 1e308], [7e7, 7e7, 7e7], [0.1, 0.0, 1e30]):
        slam.step([RobotUpdate("robot1", 2_000_000_000, np.array(odo))])
    assert slam.dropped["bad_odometry"] == 3
    assert_unchanged(before, snapshot(slam))
    # huge measurements and variances are dropped row by row; the good rows are used
    z = np.vstack([good.z, [[1e308, 1e308, 1e308]], good.z[:1]])
    cov = np.concatenate([good.cov, good.cov[:1], np.eye(3)[None] * 1e300])
    desc = np.vstack([good.descriptors, good.descriptors[:2]])
    slam.step([RobotUpdate("robot1", 2_000_000_000, np.array([0.1, 0, 0]), ObservationSet("robot1", 0, z, cov, desc))])
    assert slam.dropped["bad_observation"] == 2
    sight = RobotSighting("robot1", "robot2", np.array([1e308, 1e308]), np.diag([1e300, 1e300]))
    slam.step([RobotUpdate("robot1", 2_100_000_000, np.zeros(3), sightings=[sight])])
    assert slam.dropped["bad_sighting"] == 1
    assert_finite(slam)
