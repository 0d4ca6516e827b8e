"""The central mapper: stamp order across robots, bounded waits, pairing with odometry, counted drops."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mrslam_core.geometry.se2 import compose
from mrslam_core.pipelines.central import CentralConfig, CentralMapper
from mrslam_core.slam.config import FilterConfig
from mrslam_core.types import ObservationSet

S = 1_000_000_000


def _cfg(**kw) -> CentralConfig:
    base = dict(robots=("robot1", "robot2"), start_poses=(0.0, 0.0, 0.0, 0.0, 1.0, 0.0),
                filter=FilterConfig(num_particles=20, seed=3), max_wait=1.0)
    base.update(kw)
    return CentralConfig(**base)


def _obs(robot: str, t: float, n: int = 3) -> ObservationSet:
    rng = np.random.default_rng(int(t * 10) + len(robot))
    z = np.column_stack([rng.uniform(1, 3, n), rng.uniform(-1, 1, n), rng.uniform(0, 1, n)])
    return ObservationSet(robot, int(round(t * S)), z, np.tile(np.eye(3) * 0.01, (n, 1, 1)))


def _odom(mapper: CentralMapper, robot: str, until: float, start: float = 0.0) -> None:
    for t in np.arange(start, until + 1e-9, 0.1):
        mapper.add_odometry(robot, int(round(t * S)), np.array([0.5 * t, 0.0, 0.0]))


def _order(done) -> list[tuple[str, float]]:
    return [(d.robot, round(d.stamp_ns / S, 3)) for d in done]


def _assert_same_state(a: dict, b: dict, where: str = "") -> None:
    """Two part states (JSON values and arrays) hold the same keys and values."""
    assert sorted(a) == sorted(b), where
    for key, va in a.items():
        if isinstance(va, np.ndarray):
            np.testing.assert_array_equal(va, b[key], err_msg=f"{where}{key}")
            assert va.dtype == b[key].dtype, f"{where}{key}"
        elif isinstance(va, dict):
            _assert_same_state(va, b[key], f"{where}{key}.")
        else:
            assert va == b[key], f"{where}{key}"


def _assert_same_mapper_state(a: CentralMapper, b: CentralMapper) -> None:
    sa, sb = a.state(), b.state()
    assert sorted(sa) == sorted(sb) == ["corrections", "lifecycle", "mapper", "ordering"]
    for part in sa:
        _assert_same_state(sa[part], sb[part], f"{part}.")


def test_sets_wait_for_the_other_robot_and_go_in_stamp_order():
    m = CentralMapper(_cfg())
    _odom(m, "robot1", 5)
    _odom(m, "robot2", 5)
    m.add_observations(_obs("robot1", 0.2))
    m.add_observations(_obs("robot2", 0.2))
    assert _order(m.process()) == [("robot1", 0.2), ("robot2", 0.2)]
    m.add_observations(_obs("robot2", 0.6))
    m.add_observations(_obs("robot2", 0.4))
    assert m.process() == []  # robot1 has only reached 0.2: both robot2 sets wait
    m.add_observations(_obs("robot1", 0.5))
    assert _order(m.process()) == [("robot2", 0.4), ("robot1", 0.5)]
    assert m.queued == 1
    m.add_observations(_obs("robot1", 0.8))
    assert _order(m.process()) == [("robot2", 0.6)]  # robot1@0.8 now waits for robot2


def test_a_silent_robot_delays_the_team_by_at_most_max_wait():
    m = CentralMapper(_cfg(max_wait=1.0))
    _odom(m, "robot1", 5)
    _odom(m, "robot2", 5)
    m.add_observations(_obs("robot1", 0.2))
    m.add_observations(_obs("robot2", 0.2))
    m.process()
    out = []
    for t in (0.4, 0.6, 0.8, 1.0, 1.2, 1.4):  # robot2 has gone silent
        m.add_observations(_obs("robot1", t))
        out += _order(m.process())
    # robot2 (last heard at 0.2 s) counts as silent once the newest stamp is more than 1 s later
    assert out == [("robot1", 0.4), ("robot1", 0.6), ("robot1", 0.8), ("robot1", 1.0), ("robot1", 1.2), ("robot1", 1.4)]
    assert m.process() == [] and m.queued == 0
    m.add_observations(_obs("robot2", 1.6))  # back: waited for again
    m.add_observations(_obs("robot1", 1.8))
    assert _order(m.process()) == [("robot2", 1.6)] and m.queued == 1


def test_a_robot_not_heard_yet_is_waited_for_at_the_start_only():
    m = CentralMapper(_cfg(max_wait=1.0))
    _odom(m, "robot1", 5)
    m.add_observations(_obs("robot1", 0.2))
    m.add_observations(_obs("robot1", 1.1))
    assert m.process() == []
    m.add_observations(_obs("robot1", 1.4))
    assert _order(m.process()) == [("robot1", 0.2), ("robot1", 1.1), ("robot1", 1.4)]


def test_odometry_is_interpolated_at_the_set_and_the_first_update_starts_at_the_start_pose():
    m = CentralMapper(_cfg(filter=FilterConfig(num_particles=50, seed=1, initial_pose_sigma=(0.0, 0.0, 0.0))))
    _odom(m, "robot1", 2)
    _odom(m, "robot2", 2)
    m.add_observations(_obs("robot1", 0.25))
    m.add_observations(_obs("robot2", 0.25))
    done = m.process()
    np.testing.assert_allclose(done[0].odom, [0.125, 0.0, 0.0], atol=1e-12)  # between 0.2 and 0.3
    # robot2 starts at (0, 1, 0): its odometry moved 0.125 m along x
    assert abs(done[1].pose[0] - 0.125) < 0.05 and abs(done[1].pose[1] - 1.0) < 0.05


def test_bad_input_is_counted_and_leaves_the_filter_alone():
    m = CentralMapper(_cfg())
    _odom(m, "robot1", 1)
    _odom(m, "robot2", 1)
    assert not m.add_odometry("robot9", 0, np.zeros(3))
    assert not m.add_odometry("robot1", int(0.5 * S), np.zeros(3))  # back in time
    assert not m.add_odometry("robot1", int(1.0 * S), np.zeros(3))  # duplicate stamp
    assert not m.add_odometry("robot1", int(2.0 * S), np.array([np.nan, 0, 0]))
    assert not m.add_observations(_obs("robot9", 0.2))
    assert m.add_observations(_obs("robot1", 0.2))
    assert not m.add_observations(_obs("robot1", 0.2))  # duplicate while queued
    m.add_observations(_obs("robot2", 0.2))
    m.process()
    assert not m.add_observations(_obs("robot1", 0.1))  # older than robot1's last update
    m.add_observations(_obs("robot1", 3.0))  # no odometry there yet
    m.add_observations(_obs("robot2", 3.0))
    assert m.process() == []  # waits for robot1's odometry
    m.add_observations(_obs("robot2", 4.5))
    m.add_observations(_obs("robot1", 4.5))
    m.process()  # 3.0 is overdue now: robot1's is dropped, robot2's has no odometry either
    assert m.drops == {"unknown_robot": 2, "odometry_out_of_order": 1, "odometry_duplicate_stamp": 1,
                       "bad_odometry": 1, "duplicate_stamp": 1, "stale_stamp": 1, "no_odometry_at_stamp": 2}
    assert m.slam.steps == 2


def test_sightings_that_come_apart_from_their_set_join_it():
    """The SLAM node's ``sightings`` topic: a sighting before its set is held and joins it, one
    after it joins it in the queue, one whose set never came goes alone once a newer set is in
    (or at a flush), one for a processed stamp is counted; held ones are in the checkpoint."""
    from mrslam_core.types import RobotSighting

    m = CentralMapper(_cfg())
    _odom(m, "robot1", 3)
    _odom(m, "robot2", 3)
    seen = RobotSighting("robot1", "robot2", np.array([1.0, np.pi / 2]), np.eye(2) * 0.01)
    assert m.add_sightings("robot1", int(1.0 * S), [seen])       # before its set
    m.add_observations(_obs("robot1", 1.0))
    m.add_observations(_obs("robot1", 1.2))
    assert m.add_sightings("robot1", int(1.2 * S), [seen, seen])  # after it, while queued
    assert m.add_sightings("robot1", int(1.3 * S), [seen])       # its set never comes
    m.add_observations(_obs("robot1", 1.4))
    assert m.add_sightings("robot1", int(1.35 * S), [seen])      # after a newer set: alone, then
    m.add_observations(_obs("robot1", 1.35))                       # its set comes late and joins it
    assert m.add_sightings("robot1", int(1.6 * S), [seen])       # held at the checkpoint
    queued = {o.stamp_ns: (len(o), len(o.sightings)) for *_, o in m.ordering._queue}
    assert queued == {int(1.0 * S): (3, 1), int(1.2 * S): (3, 2), int(1.3 * S): (0, 1), int(1.35 * S): (3, 1),
                      int(1.4 * S): (3, 0)}
    state = m.ordering.state()
    fresh = CentralMapper(_cfg())
    fresh.ordering.load_state(state)
    _assert_same_state(state, fresh.ordering.state())
    assert not m.add_sightings("robot1", int(1.0 * S), [replace(seen, observer="robot2")])
    done = m.process(flush=True)
    assert _order(done) == [("robot1", 1.0), ("robot1", 1.2), ("robot1", 1.3), ("robot1", 1.35), ("robot1", 1.4),
                            ("robot1", 1.6)]
    assert not m.add_sightings("robot1", int(1.5 * S), [seen])
    assert m.drops == {"unknown_robot": 1, "stale_sighting": 1}


def test_a_set_inside_a_hole_in_the_odometry_is_dropped_not_interpolated():
    m = CentralMapper(_cfg(robots=("robot1",), start_poses=(0.0, 0.0, 0.0)))
    _odom(m, "robot1", 2.0)
    _odom(m, "robot1", 6.0, start=4.5)  # 2.5 s without odometry (the central node was down)
    for t in (1.0, 3.0, 4.4, 5.0):
        m.add_observations(_obs("robot1", t))
    done = m.process(flush=True)
    assert _order(done) == [("robot1", 1.0), ("robot1", 5.0)]
    assert m.drops == {"odometry_gap": 2}


def test_queue_overflow_drops_the_oldest():
    m = CentralMapper(_cfg(max_queue=3))
    _odom(m, "robot1", 2)
    m.add_observations(_obs("robot2", 0.1))
    for t in (0.2, 0.3, 0.4, 0.5):
        m.add_observations(_obs("robot1", t))  # wait for robot2 (heard at 0.1) until 1.1 s
    assert m.drops["queue_overflow"] == 2 and m.queued == 3


def test_the_same_messages_in_another_arrival_order_give_the_same_estimates():
    rng = np.random.default_rng(0)
    msgs = []
    truth = {"robot1": np.zeros(3), "robot2": np.array([0.0, 1.0, 0.0])}
    for i in range(1, 40):
        t = i * 0.2
        for r in truth:
            truth[r] = compose(truth[r], np.array([0.1, 0.0, 0.05]))
            msgs.append(("odom", r, t, truth[r] - (0 if r == "robot1" else np.array([0.0, 1.0, 0.0]))))
            msgs.append(("obs", r, t, None))
    # arrival order 1: odometry first; arrival order 2: each robot's observations late and shuffled
    late = sorted(msgs, key=lambda m: (m[2] + (0.3 if m[0] == "obs" else 0.0) + rng.uniform(0, 0.15), m[1]))
    odom0 = [("odom", r, 0.0, np.zeros(3)) for r in truth]
    runs = []
    for order in (msgs, late):
        m = CentralMapper(_cfg())
        for kind, r, t, pose in odom0 + order:
            if kind == "odom":
                m.add_odometry(r, int(round(t * S)), pose)
            else:
                m.add_observations(_obs(r, t, 6))
                m.process()
        m.process(flush=True)
        runs.append(m.trajectories())
    for r in truth:
        np.testing.assert_array_equal(runs[0][r][0], runs[1][r][0])
        np.testing.assert_array_equal(runs[0][r][1], runs[1][r][1])


def _until_1_s(m: CentralMapper) -> CentralMapper:
    """Both robots' odometry to 6 s and sets at 0.2-0.8 s; robot1's set at 1.0 s is queued."""
    _odom(m, "robot1", 6)
    _odom(m, "robot2", 6)
    for t in (0.2, 0.4, 0.6, 0.8):
        m.add_observations(_obs("robot1", t, 5))
        m.add_observations(_obs("robot2", t, 5))
        m.process()
    m.add_observations(_obs("robot1", 1.0, 5))  # queued: waits for robot2
    return m


def _after_1_s(m: CentralMapper) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    for t in (1.0, 1.2, 1.4):
        m.add_observations(_obs("robot2", t, 5))
        if t > 1.0:
            m.add_observations(_obs("robot1", t, 5))
        m.process()
    m.process(flush=True)
    return m.trajectories()


def _assert_same_trajectories(ta: dict, tb: dict) -> None:
    assert sorted(ta) == sorted(tb)
    for r in ta:
        np.testing.assert_array_equal(ta[r][0], tb[r][0])
        np.testing.assert_array_equal(ta[r][1], tb[r][1])


def test_a_resumed_mapper_continues_exactly_like_the_original(tmp_path):
    a = _until_1_s(CentralMapper(_cfg()))
    assert a.queued == 1
    a.save(tmp_path / "ckpt.npz")
    b = CentralMapper.resume(_cfg(), tmp_path / "ckpt.npz")
    assert b.queued == 1 and b.drops == a.drops and len(b.update_ms) == len(a.update_ms)
    _assert_same_mapper_state(a, b)
    ta, tb = _after_1_s(a), _after_1_s(b)
    _assert_same_trajectories(ta, tb)
    assert len(ta["robot1"][0]) == 7


def test_a_version_2_checkpoint_resumes_with_the_fields_it_lacks_at_their_defaults():
    """data/central_v2.npz was written by the version 2 ``CentralMapper.save`` (commit d722544)
    after ``_until_1_s`` (its members deflated, their bytes unchanged); resumed, the mapper holds
    the state a straight run has at that point and continues exactly like it."""
    from pathlib import Path

    from mrslam_core.slam.checkpoint import read_header

    path = Path(__file__).parent / "data" / "central_v2.npz"
    assert read_header(path)["version"] == 2
    straight = _until_1_s(CentralMapper(_cfg()))
    old = CentralMapper.resume(_cfg(), path)
    assert old.merges == [] and old.relocalizations == [] and old.local == {} and old.queued == 1
    a, b = straight.state(), old.state()
    for state in (a, b):
        state["mapper"].pop("update_ms")  # wall times
        state["ordering"]["queue"] = [e[:2] for e in state["ordering"]["queue"]]  # version 2 kept no arrival numbers
    for part in a:
        _assert_same_state(a[part], b[part], f"{part}.")
    _assert_same_trajectories(_after_1_s(straight), _after_1_s(old))


def test_resume_refuses_a_checkpoint_of_other_robots(tmp_path):
    import pytest

    from mrslam_core.slam.checkpoint import CheckpointError

    a = CentralMapper(_cfg())
    a.save(tmp_path / "ckpt.npz")
    with pytest.raises(CheckpointError, match="robots"):
        CentralMapper.resume(_cfg(robots=("robot1", "robot3")), tmp_path / "ckpt.npz")


def test_a_robot_with_an_unknown_start_is_merged_and_then_localised_in_the_map():
    from mrslam_core.datasets.synthetic import SyntheticWorld, SyntheticWorldConfig
    from mrslam_core.fusion.config import FusionConfig

    world = SyntheticWorld(SyntheticWorldConfig(num_robots=2, seed=5))
    starts = world.start_poses()
    cfg = CentralConfig(robots=("robot1", "robot2"), start_poses=(*starts[0], 9.0, 9.0, 9.0),  # robot2's: not used
                        unknown_start=("robot2",), merge_every=5,
                        filter=FilterConfig(num_particles=50, seed=2), fusion=FusionConfig())
    m = CentralMapper(cfg)
    odom = {r: np.zeros(3) for r in world.robots}
    for r in world.robots:
        m.add_odometry(r, 0, odom[r])
    truth = {}
    merged_at = None
    for i, (_, true, _, updates) in enumerate(world.run(80)):
        for k, u in enumerate(updates):
            odom[u.robot] = compose(odom[u.robot], u.odometry)
            m.add_odometry(u.robot, u.stamp_ns, odom[u.robot])
            truth[(u.robot, u.stamp_ns)] = true[k]
            m.add_observations(u.observations)
        for d in m.process():
            if d.robot == "robot2" and d.merged and merged_at is None:
                merged_at = i
    assert "robot2" not in m.local and merged_at is not None, m.merges[-3:]
    assert m.merges[-1]["accepted"] and not any(x["accepted"] for x in m.merges[:-1])
    t, poses = m.trajectories()["robot2"]
    assert len(t) >= 80 - merged_at - 2
    err = [np.linalg.norm(p[:2] - truth[("robot2", s)][:2]) for s, p in zip(t, poses)]
    assert np.sqrt(np.mean(np.square(err))) < 0.15, err  # 0.016 m measured (filter seeds 2 10 20 30 40 50: 0.016 0.073 0.037 0.013 0.070 0.084)
    assert m.trajectories()["robot1"][0].size >= 79


def _reading(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(range [m], bearing [rad]) of pose b seen from pose a (both (3,), map frame)."""
    d = b[:2] - a[:2]
    return np.array([np.hypot(*d), np.arctan2(d[1], d[0]) - a[2]])


def _rendezvous_run(resume_in: Path | None = None, resume_at: int = -1) -> tuple[CentralMapper, dict, list[int]]:
    """robot2 (no start pose, alignments off) and robot1 read each other at steps 20 and 22
    (exact readings, stated σ 0.05 m / 0.02 rad), robot1 alone reads robot2 at step 10; with
    ``resume_in`` the mapper is saved and resumed after step ``resume_at``. Returns the mapper, the
    true poses by (robot, stamp) and robot2's stamps."""

    from mrslam_core.datasets.synthetic import SyntheticWorld, SyntheticWorldConfig
    from mrslam_core.fusion.config import FusionConfig
    from mrslam_core.types import RobotSighting

    world = SyntheticWorld(SyntheticWorldConfig(num_robots=2, seed=5))
    starts = world.start_poses()
    cfg = CentralConfig(robots=("robot1", "robot2"), start_poses=(*starts[0], 9.0, 9.0, 9.0),
                        unknown_start=("robot2",), merge_every=10**6, rendezvous=True,
                        filter=FilterConfig(num_particles=50, seed=2), fusion=FusionConfig())
    m = CentralMapper(cfg)
    cov = np.diag([0.05**2, 0.02**2])
    odom = {r: np.zeros(3) for r in world.robots}
    for r in world.robots:
        m.add_odometry(r, 0, odom[r])
    truth = {}
    for i, (_, true, _, updates) in enumerate(world.run(30)):
        for k, u in enumerate(updates):
            odom[u.robot] = compose(odom[u.robot], u.odometry)
            m.add_odometry(u.robot, u.stamp_ns, odom[u.robot])
            truth[(u.robot, u.stamp_ns)] = true[k]
            obs = u.observations
            other = 1 - k
            if i in (20, 22) or (i == 10 and k == 0):
                z = _reading(true[k], true[other])
                obs = replace(obs, sightings=(RobotSighting(u.robot, world.robots[other], z, cov),))
            m.add_observations(obs)
        m.process()
        if resume_in is not None and i == resume_at:
            m = CentralMapper.resume(cfg, m.save(resume_in / "ckpt.npz"))
    return m, truth, sorted({s for r, s in truth if r == "robot2"})


def test_a_robot_with_an_unknown_start_joins_on_the_second_mutual_sighting():
    """Rendezvous in the mapper (``rendezvous``): the first mutual sighting (step 20) is held, the
    second (step 22) agrees and joins robot2 at its true pose (its transform 0.05 m / 1.2° off the
    true start; robot2 tracked within 0.062 m after it); the one-way reading of step 10 joins
    nothing."""
    m, truth, stamps = _rendezvous_run()
    tried = [(e["stamp_ns"], e["via"], e["accepted"]) for e in m.merges]
    assert tried == [(stamps[20], "rendezvous with robot1", False),
                     (stamps[22], "rendezvous with robot1", True)], m.merges
    assert "held until a second piece of evidence" in m.merges[0]["reason"]
    assert "robot2" not in m.local
    t, poses = m.trajectories()["robot2"]
    assert t[0] == stamps[22]
    err = [np.linalg.norm(p[:2] - truth[("robot2", s)][:2]) for s, p in zip(t, poses)]
    assert max(err) < 0.1, err


def test_a_mapper_resumed_between_two_mutual_sightings_joins_as_without_the_checkpoint(tmp_path):
    """The held sighting and the readings are in the checkpoint: resumed after step 21, the second
    sighting joins robot2 at the same step and to the same poses."""
    a, _, _ = _rendezvous_run()
    b, _, _ = _rendezvous_run(resume_in=tmp_path, resume_at=21)
    assert a.merges == b.merges
    _assert_same_trajectories(a.trajectories(), b.trajectories())


def _world(n: int = 300, seed: int = 4) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    pts = np.column_stack([rng.uniform(-1, 8, n), rng.uniform(-4, 4, n), rng.uniform(0, 2, n)])
    return pts, rng.uniform(0, 1, (n, 16)).astype(np.float32)


def _seen(robot: str, t: float, pose: np.ndarray, pts: np.ndarray, desc: np.ndarray, seed: int) -> ObservationSet:
    """Stereo points (base_link) of the landmarks 0.5-4 m ahead within ±45°, 1 cm noise."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    d = pts[:, :2] - pose[:2]
    local = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], pts[:, 2]])
    rng_ = np.linalg.norm(local[:, :2], axis=1)
    vis = (local[:, 0] > 0.5) & (rng_ < 4.0) & (np.abs(np.arctan2(local[:, 1], local[:, 0])) < np.pi / 4)
    z = local[vis] + np.random.default_rng(seed).normal(0, 0.01, (int(vis.sum()), 3))
    return ObservationSet(robot, int(round(t * S)), z, np.tile(np.eye(3) * 1e-4, (len(z), 1, 1)), desc[vis])


def _gap_run(truth_after: np.ndarray, blind: bool = False, **kw) -> tuple[CentralMapper, np.ndarray]:
    """robot1 drives along x at 0.5 m/s with exact odometry and observations until 2 s, is
    silent until 10 s (``blind``: its sets hold no points) (odometry: out to x = 2 and back,
    2 m), and is then at ``truth_after`` while its odometry says (1, 0, 0)."""
    from mrslam_core.slam.config import AssociationConfig

    pts, desc = _world()
    m = CentralMapper(CentralConfig(robots=("robot1",), start_poses=(0.0, 0.0, 0.0),
                                    filter=FilterConfig(num_particles=50, seed=3, proposal="fastslam2",
                                                        association=AssociationConfig(descriptor_gate=0.25)), **kw))
    for i, t in enumerate(np.arange(0.0, 10.01, 0.2)):
        x = 0.5 * t if t <= 2.0 else 1.0 + np.sin(np.pi * (t - 2.0) / 8.0)
        m.add_odometry("robot1", int(round(t * S)), np.array([x, 0.0, 0.0]))
        if t <= 2.0 + 1e-9:
            m.add_observations(_seen("robot1", t, np.array([0.5 * t, 0.0, 0.0]), pts, desc, i))
        elif blind and t < 10.0 - 1e-9:
            m.add_observations(ObservationSet("robot1", int(round(t * S)), np.zeros((0, 3)), np.zeros((0, 3, 3)),
                                              np.zeros((0, desc.shape[1]), np.float32)))
    m.add_observations(_seen("robot1", 10.0, truth_after, pts, desc, 99))
    done = m.process(flush=True)
    return m, done[-1].pose


def test_a_robot_back_from_a_gap_is_placed_by_its_observations():
    """Its dead reckoning over the silent 8 s is 0.4 m and 0.1 rad off; the set after the gap,
    aligned to the map, puts it back (without re-localisation it stays where odometry says)."""
    truth = np.array([1.0, 0.4, 0.1])
    m, pose = _gap_run(truth)
    (e,) = m.relocalizations
    assert e["accepted"] and e["inliers"] >= 6 and abs(e["gap_s"] - 8.0) < 1e-9 and abs(e["travelled_m"] - 2.0) < 0.01
    assert np.hypot(*(pose[:2] - truth[:2])) < 0.03 and abs(pose[2] - truth[2]) < 0.01, pose
    m, pose = _gap_run(truth, relocalize_after=0.0)
    assert m.relocalizations == [] and np.hypot(*(pose[:2] - truth[:2])) > 0.3, pose


def test_a_robot_blind_for_longer_than_the_gap_is_not_taken_for_silent():
    """Sets without points for 8 s move the robot by odometry alone, but it was not silent: the
    gap is the 0.2 s since its previous (empty) set and no re-localisation is tried."""
    truth = np.array([1.0, 0.4, 0.1])
    m, pose = _gap_run(truth, blind=True)
    assert m.relocalizations == [] and np.hypot(*(pose[:2] - truth[:2])) > 0.3, pose


def test_a_fit_far_from_dead_reckoning_is_not_used():
    """1.5 m from where odometry says, beyond where a lost robot may be after the gap (0.5 m + 10 %
    of 2 m): the fit is weighed and logged, no particle finds the robot lost, and the particles
    stay with the odometry."""
    truth = np.array([1.0, 1.5, 0.0])
    m, pose = _gap_run(truth)
    (e,) = m.relocalizations
    assert e["lost"] == 0.0 and e["p_lost"] < 1e-100 and abs(e["shift_m"] - 1.5) < 0.05, e
    assert np.hypot(*(pose[:2] - [1.0, 0.0])) < 0.3


def test_the_motion_over_a_gap_is_sampled_before_the_set_is_associated():
    """A set 3 s after the robot's previous one: the filter first moves the robot without
    observations to 0.2 s before the set (each particle draws its own noise), then applies the
    set with the last 0.2 s of motion; the two parts compose to the odometry exactly."""
    from mrslam_core.slam.config import MotionConfig

    still = MotionConfig(alpha1=0.0, alpha2=0.0, alpha3=0.0, alpha4=0.0)
    for gap_rule, steps in ((1.0, 2), (0.0, 1)):
        m = CentralMapper(_cfg(robots=("robot1",), start_poses=(0.0, 0.0, 0.0), sample_gap=gap_rule,
                               filter=FilterConfig(num_particles=20, seed=3, motion=still)))
        for t in np.arange(0.0, 4.01, 0.1):
            m.add_odometry("robot1", int(round(t * S)), np.array([0.5 * t, 0.1 * t, 0.2 * t]))
        m.add_observations(_obs("robot1", 0.2))
        m.process()
        before = m.slam.steps
        m.add_observations(_obs("robot1", 3.2))
        (done,) = m.process(flush=True)
        assert m.slam.steps - before == steps
        np.testing.assert_allclose(done.pose, [1.6, 0.32, 0.64], atol=1e-9)
        assert m.slam.last_stamp["robot1"] == int(3.2 * S)


def _silent_from_2_s(until: float, pts: np.ndarray, desc: np.ndarray) -> CentralMapper:
    """robot1 drives along x at 0.5 m/s seeing the world until 2 s, then only its odometry (out
    to x = 2 and back to 1 by 10 s) arrives until ``until`` [s]."""
    m = CentralMapper(CentralConfig(robots=("robot1",), start_poses=(0.0, 0.0, 0.0),
                                    filter=FilterConfig(num_particles=50, seed=3, proposal="fastslam2")))
    for i, t in enumerate(np.arange(0.0, until + 0.01, 0.2)):
        x = 0.5 * t if t <= 2.0 else 1.0 + np.sin(np.pi * min(t - 2.0, 8.0) / 8.0)
        m.add_odometry("robot1", int(round(t * S)), np.array([x, 0.0, 0.0]))
        if t <= 2.0 + 1e-9:
            m.add_observations(_seen("robot1", t, np.array([0.5 * t, 0.0, 0.0]), pts, desc, i))
    return m


TRUTH_AFTER_GAP = np.array([1.0, 0.4, 0.1])


def _first_try() -> tuple[CentralMapper, list, np.ndarray, np.ndarray]:
    """robot1 back from the gap of ``_silent_from_2_s``: its first set, at 10 s, holds only 7
    landmarks bunched together (no fit), the next one, at 10.4 s, is complete but comes within a
    second of that try. Returns the mapper, its updates, the world's points and descriptors."""
    pts, desc = _world()
    m = _silent_from_2_s(11.0, pts, desc)
    full = _seen("robot1", 10.0, TRUTH_AFTER_GAP, pts, desc, 99)
    bunch = np.argsort(np.linalg.norm(full.z - full.z[0], axis=1))[:7]
    m.add_observations(ObservationSet("robot1", full.stamp_ns, full.z[bunch], full.cov[bunch], full.descriptors[bunch]))
    m.add_observations(_seen("robot1", 10.4, TRUTH_AFTER_GAP, pts, desc, 104))
    return m, m.process(flush=True), pts, desc


def _two_tries(resume_in: Path | None = None) -> tuple[CentralMapper, list]:
    """``_first_try``, then complete sets at 10.8 and 11.0 s; with ``resume_in`` (a folder), the
    mapper is saved and resumed before them."""
    m, done, pts, desc = _first_try()
    if resume_in is not None:
        m = CentralMapper.resume(m.cfg, m.save(resume_in / "ckpt.npz"))
    m.add_observations(_seen("robot1", 10.8, TRUTH_AFTER_GAP, pts, desc, 108))
    m.add_observations(_seen("robot1", 11.0, TRUTH_AFTER_GAP, pts, desc, 110))
    return m, done + m.process(flush=True)


def test_a_robot_back_from_a_gap_gets_more_than_one_try():
    """The bunched set cannot be aligned; the sets in between move the robot by odometry only (a
    lost robot is left to its odometry between tries); the set a second after the first try
    re-localises it."""
    m, done = _two_tries()
    first, second = m.relocalizations
    assert not first["accepted"] and second["accepted"] and second["stamp_ns"] == 11 * S, m.relocalizations
    assert m.drops["awaiting_relocalization"] == 3
    assert np.hypot(*(done[-1].pose[:2] - TRUTH_AFTER_GAP[:2])) < 0.03, done[-1].pose


def test_a_mapper_resumed_between_two_tries_continues_exactly(tmp_path):
    """Saved while the robot awaits its second try: the robot awaiting it, its last try and the
    refused fit are in the checkpoint (version 2 left them out: the resumed robot was never placed
    again and stayed 0.4 m off, at its dead reckoning), so the resumed mapper places it at the
    same set, at the same poses."""
    a, _ = _two_tries()
    b, _ = _two_tries(resume_in=tmp_path)
    assert a.relocalizations == b.relocalizations and b.relocalizations[-1]["accepted"]
    assert a.drops == b.drops
    _assert_same_trajectories(a.trajectories(), b.trajectories())


def _restart_run(reset_speed: float, restart_at: int = 30, steps: int = 90,
                 resume_in: Path | None = None, resume_at: int = -1, seed: int = 2) -> tuple[CentralMapper, dict, list]:
    """Two robots with known starts in the synthetic stereo world; robot2's odometry restarts
    from (0, 0, 0) at step ``restart_at`` (its driver restarted where it stood); with
    ``resume_in`` (a folder), the mapper is saved and resumed after step ``resume_at``; ``seed``:
    the filter's."""
    from mrslam_core.datasets.synthetic import SyntheticWorld, SyntheticWorldConfig
    from mrslam_core.fusion.config import FusionConfig

    world = SyntheticWorld(SyntheticWorldConfig(num_robots=2, seed=5))
    cfg = CentralConfig(robots=("robot1", "robot2"), start_poses=tuple(world.start_poses().ravel()),
                        merge_every=5, odom_reset_speed=reset_speed,
                        filter=FilterConfig(num_particles=50, seed=seed), fusion=FusionConfig())
    m = CentralMapper(cfg)
    odom = {r: np.zeros(3) for r in world.robots}
    for r in world.robots:
        m.add_odometry(r, 0, odom[r])
    truth, merged = {}, []
    for i, (_, true, _, updates) in enumerate(world.run(steps)):
        for k, u in enumerate(updates):
            if u.robot == "robot2" and i == restart_at:
                odom["robot2"] = np.zeros(3)
            odom[u.robot] = compose(odom[u.robot], u.odometry)
            m.add_odometry(u.robot, u.stamp_ns, odom[u.robot])
            truth[(u.robot, u.stamp_ns)] = true[k]
            m.add_observations(u.observations)
        merged += [(i, d.merged) for d in m.process() if d.robot == "robot2"]
        if resume_in is not None and i == resume_at:
            m = CentralMapper.resume(cfg, m.save(resume_in / "ckpt.npz"))
    return m, truth, merged


def _error_after(m: CentralMapper, truth: dict, robot: str, after_ns: int) -> float:
    t, poses = m.trajectories()[robot]
    err = [np.linalg.norm(p[:2] - truth[(robot, s)][:2]) for s, p in zip(t, poses) if s > after_ns]
    return float(np.sqrt(np.mean(np.square(err))))


def test_a_robot_whose_odometry_restarts_is_mapped_on_its_own_and_merged_again():
    """robot2's odometry jumps back to the origin at step 30 (its driver restarted): the jump is
    counted, robot2 has no map pose until its new map aligns with the team's (2 s later, 15
    inliers), and after the merge it is about as well localised as in the same run without a
    restart.
    Without the reset check the filter takes the jump for motion and robot2 stays metres off."""
    m, truth, merged = _restart_run(reset_speed=2.0)
    assert [r["robot"] for r in m.restarts] == ["robot2"] and m.drops["odometry_reset"] == 1
    assert m.restarts[0]["jump_m"] > 1.0
    restart_ns = m.restarts[0]["stamp_ns"]
    back = [i for i, ok in merged if ok and i > 30]
    assert "robot2" not in m.local and back, m.merges[-3:]
    assert not any(ok for i, ok in merged if 30 <= i < back[0])  # no map pose while it maps on its own
    assert m.merges[-1]["accepted"] and m.merges[-1]["robot"] == "robot2"
    assert _error_after(m, truth, "robot1", 0) < 0.15
    # as issue 8 measures a join: within 1.5x of the same run without the restart. One run is one
    # draw of the filter (this seed: 0.350 / 0.285 m = 1.23; the robot drifts in unmapped ground
    # after its join until its loop closes at 40 s), so the median over five filter seeds: ratios
    # 1.23 1.21 1.11 0.88 2.68 (median 1.21)
    ratios = []
    for seed in (2, 10, 20, 30, 40):
        r, tr, _ = _restart_run(reset_speed=2.0, seed=seed)
        plain, truth_plain, _ = _restart_run(reset_speed=2.0, restart_at=-1, seed=seed)
        assert plain.restarts == [] and len(r.restarts) == 1
        at = r.restarts[0]["stamp_ns"]
        ratios.append(_error_after(r, tr, "robot2", at) / _error_after(plain, truth_plain, "robot2", at))
    assert np.median(ratios) < 1.5, ratios

    off, truth_off, _ = _restart_run(reset_speed=0.0)
    assert off.restarts == [] and _error_after(off, truth_off, "robot2", restart_ns) > 1.0


def test_a_restarted_robot_not_merged_at_the_checkpoint_merges_as_without_the_checkpoint(tmp_path):
    """Saved at step 32 (16.5 s), while robot2 maps on its own since its restart at step 30: its
    local filter and its update count are in the checkpoint (version 2 left them out: robot2
    started its map again and merged at 19 s, not 17.5 s), so the resumed mapper merges robot2 at
    the same update, to the same poses."""
    a, _, merged_a = _restart_run(reset_speed=2.0)
    b, _, merged_b = _restart_run(reset_speed=2.0, resume_in=tmp_path, resume_at=32)
    assert [(e["stamp_ns"], e["accepted"]) for e in a.merges] == [(17_500_000_000, True)]
    assert merged_a == merged_b and a.merges == b.merges and a.restarts == b.restarts
    _assert_same_trajectories(a.trajectories(), b.trajectories())


@pytest.fixture(scope="module")
def mid_run_mappers() -> list[CentralMapper]:
    """Mappers in the middle of what version 2 checkpoints left out: robot2 restarted and mapping
    on its own (after step 32), and merged (after step 35); a robot awaiting its second try after a gap
    (``_first_try``); a robot between two map checks (12.5 s of ``_slip_feed``)."""
    restarted, _, _ = _restart_run(reset_speed=2.0, steps=33)
    merged, _, _ = _restart_run(reset_speed=2.0, steps=36)
    back = _first_try()[0]
    checking = CentralMapper(_slip_cfg(every=1.0, age=3.0))
    _slip_feed(checking, 0.0, 12.5)
    assert "robot2" in restarted.local and restarted.lifecycle.state()["local_updates"] == {"robot2": 3}
    assert merged.merges and not merged.local
    assert back.relocalizations and back.corrections.state()["returning"]
    assert checking.corrections.state()["recent"]
    return [restarted, merged, back, checking]


def test_every_attribute_of_a_part_is_in_its_state_or_comes_from_the_config():
    """A part that gains an attribute must save it in ``state()`` and take it in ``load_state()``
    (then list it here): a checkpoint that lists fields by hand missed some before. Not in the
    state: the config and what follows from it (``cfg``, ``robots``, ``_robots``, ``_known``,
    ``_starts``, ``_wait_ns``, ``_step_ns``), the mapper's shared ``drops`` (in the mapper's own state) and the
    queue's key set (``_queued``, rebuilt from the queue)."""
    m = CentralMapper(_cfg())
    derived = {"cfg", "robots", "_robots", "_known", "_starts", "_wait_ns", "_step_ns", "drops", "_queued"}
    assert set(vars(m.ordering)) - derived == {"now_ns", "last", "_odom", "_queue", "_seq", "_latest_obs", "_first_ns",
                                               "_held"}
    assert set(vars(m.lifecycle)) - derived == {"local", "_updates", "merges", "restarts", "gate", "_readings"}
    assert set(vars(m.corrections)) - derived == {"relocalizations", "map_checks", "distrusted",
                                                  "_returning", "_reloc_tried", "_recent", "_checked",
                                                  "_agreed", "_unmoved"}
    assert set(vars(m)) - derived == {"slam", "lifecycle", "ordering", "corrections", "update_ms", "trajectory", "held"}


@pytest.mark.parametrize("part", ["ordering", "lifecycle", "corrections"])
def test_each_part_takes_back_its_whole_state(mid_run_mappers, part):
    for m in mid_run_mappers:
        state = getattr(m, part).state()
        fresh = getattr(CentralMapper(m.cfg), part)
        fresh.load_state(state)
        _assert_same_state(state, fresh.state(), f"{part}.")


def test_a_checkpoint_holds_every_part_whole(mid_run_mappers, tmp_path):
    for i, m in enumerate(mid_run_mappers):
        _assert_same_mapper_state(m, CentralMapper.resume(m.cfg, m.save(tmp_path / f"{i}.npz")))




def _slip_cfg(**check) -> CentralConfig:
    from mrslam_core.pipelines.central import MapCheckConfig
    from mrslam_core.slam.config import AssociationConfig

    return CentralConfig(robots=("robot1",), start_poses=(0.0, 0.0, 0.0), map_check=MapCheckConfig(**check),
                         filter=FilterConfig(num_particles=50, seed=3, proposal="fastslam2",
                                             association=AssociationConfig(descriptor_gate=0.25)))


def _slip_feed(m: CentralMapper, t0: float, t1: float) -> list:
    """robot1 drives 3 m along x mapping the landmarks ahead (exact odometry), then stands blind
    from 10 to 12 s while it turns 0.15 rad (8.6°) that its odometry does not report (wheels
    slipping against a door jamb), then sees the mapped landmarks again until 18 s: its sets
    from ``t0`` to ``t1`` [s] go in; returns the updates made."""
    pts, desc = _world()
    done = []
    for i, t in enumerate(np.arange(0.0, 18.01, 0.2)):
        if not t0 - 1e-9 <= t <= t1 + 1e-9:
            continue
        x = min(0.3 * t, 3.0)
        turn = float(np.clip((t - 10.0) / 2.0, 0.0, 1.0)) * 0.15
        m.add_odometry("robot1", int(round(t * S)), np.array([x, 0.0, 0.0]))
        if 10.0 < t < 12.0 - 1e-9:
            m.add_observations(ObservationSet("robot1", int(round(t * S)), np.zeros((0, 3)), np.zeros((0, 3, 3)),
                                              np.zeros((0, desc.shape[1]), np.float32)))
        else:
            m.add_observations(_seen("robot1", t, np.array([x, 0.0, turn]), pts, desc, i))
        done += m.process()
    return done + m.process(flush=True)


def _slip_run(**check) -> tuple[CentralMapper, np.ndarray]:
    m = CentralMapper(_slip_cfg(**check))
    return m, _slip_feed(m, 0.0, 18.0)[-1].pose


@pytest.mark.parametrize("poses", ["estimate", "odometry"])
def test_a_robot_turned_while_blind_is_moved_back_by_the_older_map(poses):
    """The map check aligns the robot's last 3 s of sets (placed by its estimates or by its
    odometry) to the landmarks older than 3 s: once the sets since the slip fill the window, every
    particle finds the robot lost (the fit is 8.6° from a pose whose spread is 0.9°, and it
    explains the frame far better), and it is moved there; every other check agrees. Without
    the check the 8.6° stay (its sets miss every landmark and are mapped again, turned)."""
    m, pose = _slip_run(every=1.0, age=3.0, poses=poses)
    (e,) = m.relocalizations
    assert e["cause"] == "map_check" and 12.0 < e["stamp_ns"] / S < 15.0 and abs(e["turn_rad"] - 0.15) < 0.02, e
    assert e["lost"] == 1.0 and e["p_lost"] > 0.999, e
    assert m.map_checks["moved"] == 1 and m.map_checks["agreed"] >= 8, m.map_checks
    assert np.hypot(*(pose[:2] - [3.0, 0.0])) < 0.05 and abs(pose[2] - 0.15) < 0.01, pose
    m, pose = _slip_run(every=0.0)
    assert m.relocalizations == [] and not m.map_checks and abs(pose[2] - 0.15) > 0.1, pose


def test_the_prior_odds_of_being_lost_decide_the_move():
    """The same slip with a prior probability of being lost of 1e-200: the frame's evidence for
    the fit (about 10^150 times that of the turned pose) does not outweigh it, and no check
    moves the robot."""
    m, pose = _slip_run(every=1.0, age=3.0, lost_probability=1e-200)
    assert m.relocalizations == [] and m.map_checks["moved"] == 0 and abs(pose[2] - 0.15) > 0.1, m.map_checks


def test_landmarks_mapped_before_a_move_are_left_out_of_later_checks():
    """The check at 12 s agreed (no set since the slip had reached it); the move at 13 s says the
    robot's landmarks born from 12 to 13 s were mapped turned by 8.6°: later checks leave slots
    of such a window out of the older map (those of 12-13 s are dropped by the move itself, so
    the exclusion is shown on the landmarks of a later window)."""
    from mrslam_core.fusion.maps import LandmarkMap

    m, _ = _slip_run(every=1.0, age=3.0, distrust_moved=False)
    assert m.corrections.distrusted == []
    m, pose = _slip_run(every=1.0, age=3.0, distrust_moved=True)
    assert m.corrections.distrusted == [(0, 12 * S, 13 * S)] and m.map_checks["moved"] == 1
    m.corrections.distrusted.append((0, 14 * S, 16 * S))
    store = m.slam.landmarks
    mine = (store.maker[: store.size] == 0) & (store.born[: store.size] >= 14 * S) & (store.born[: store.size] <= 16 * S)
    everything = LandmarkMap.from_filter(m.slam).ids
    assert np.isin(everything, np.flatnonzero(mine)).sum() > 0
    near = m.corrections.map_near(m.slam, pose, np.array([[3.0, 0.0, 0.0]]), 10.0)  # reaches every landmark
    assert sorted(near.ids.tolist()) == sorted(set(everything.tolist()) - set(np.flatnonzero(mine).tolist()))


def test_a_mapper_resumed_between_two_map_checks_continues_exactly(tmp_path):
    """Saved at 12.5 s, after the slip and before the check that moves the robot: the recent
    sets and the check clock are in the checkpoint, so the resumed mapper moves the robot at the
    same set, to the same poses."""
    a = CentralMapper(_slip_cfg(every=1.0, age=3.0))
    _slip_feed(a, 0.0, 12.5)
    assert not a.relocalizations and a.corrections.state()["recent"]
    a.save(tmp_path / "ckpt.npz")
    b = CentralMapper.resume(_slip_cfg(every=1.0, age=3.0), tmp_path / "ckpt.npz")
    _assert_same_mapper_state(a, b)
    for m in (a, b):
        _slip_feed(m, 12.7, 18.0)
    assert a.relocalizations == b.relocalizations and len(a.relocalizations) == 1
    ta, tb = a.trajectories()["robot1"], b.trajectories()["robot1"]
    np.testing.assert_array_equal(ta[0], tb[0])
    np.testing.assert_array_equal(ta[1], tb[1])


def test_a_robot_back_from_silence_with_empty_sets_first_is_still_placed_by_its_observations():
    """Silent from 2 to 10 s, then two sets without points (a frontend's tracks need three frames
    after a gap), then a full one: the empty sets do not close the gap; the full one, 0.4 s
    later, re-localises the robot."""
    pts, desc = _world()
    truth = np.array([1.0, 0.4, 0.1])
    m = _silent_from_2_s(10.4, pts, desc)
    for t in (10.0, 10.2):
        m.add_observations(ObservationSet("robot1", int(round(t * S)), np.zeros((0, 3)), np.zeros((0, 3, 3)),
                                          np.zeros((0, desc.shape[1]), np.float32)))
    m.add_observations(_seen("robot1", 10.4, truth, pts, desc, 104))
    done = m.process(flush=True)
    (e,) = m.relocalizations
    assert e["accepted"] and abs(e["gap_s"] - 8.4) < 1e-9, e
    assert np.hypot(*(done[-1].pose[:2] - truth[:2])) < 0.03, done[-1].pose
    assert m.drops["awaiting_relocalization"] == 2
    t, _ = m.trajectories()["robot1"]  # the two waiting sets have no map pose: not reported
    assert not {int(10.0 * S), int(round(10.2 * S))} & set(t.tolist()) and int(10.4 * S) in t


def test_landmarks_made_in_the_window_of_a_move_are_dropped_where_it_moved():
    """The sets of 12-13 s saw the landmarks from a pose turned by 8.6° and mapped them again,
    0.3-0.6 m from where they are. The move at 13 s says those poses were off: in the particles
    that moved the robot, the landmarks it made since the last check that confirmed it (12 s)
    are dropped, and the robot maps them again from its new pose; the landmarks made before the
    slip stay where they were. Without the map check the turned copies stay."""
    from mrslam_core.fusion.maps import LandmarkMap

    pts, desc = _world()

    def errors(m):
        best = LandmarkMap.from_filter(m.slam)
        truth = pts[np.argmin(((best.descriptors[:, None] - desc[None]) ** 2).sum(-1), axis=1)]
        return m.slam.landmarks.born[best.ids], np.hypot(*(best.means[:, :2] - truth[:, :2]).T)

    m, _ = _slip_run(every=1.0, age=3.0)
    (e,) = m.relocalizations
    assert e["stamp_ns"] == 13 * S and e["lost"] == 1.0, e
    born, err = errors(m)
    assert not ((born >= 12 * S) & (born <= 13 * S)).any(), born / S  # dropped in every particle
    assert (born > 13 * S).sum() >= 5 and err[born > 13 * S].max() < 0.05, err[born > 13 * S]
    assert (born < 10 * S).sum() >= 20 and err[born < 10 * S].max() < 0.05, err[born < 10 * S]
    born, err = errors(_slip_run(every=0.0)[0])
    assert np.median(err[born >= 12 * S]) > 0.3, err[born >= 12 * S]
