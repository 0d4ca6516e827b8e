"""U-SURF against a direct computation, tracking, the choice of B, obstacle scans, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from mrslam_core.configio import ConfigError, from_dict, to_dict
from mrslam_core.frontend import Frontend, FrontendConfig
from mrslam_core.frontend.features import harris
from mrslam_core.frontend.obstacles import scan_from_points
from mrslam_core.frontend.spread import select_spread
from mrslam_core.frontend.tracking import Tracker
from mrslam_core.frontend.usurf import haar_responses, usurf


def test_haar_responses_equal_direct_box_sums():
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (30, 40), dtype=np.uint8)
    dx, dy = haar_responses(img, 2)
    f = img.astype(np.int64)
    for v, u in [(10, 10), (5, 20), (20, 33)]:
        exp_dx = f[v - 2: v + 3, u + 1: u + 3].sum() - f[v - 2: v + 3, u - 2: u].sum()
        exp_dy = f[v + 1: v + 3, u - 2: u + 3].sum() - f[v - 2: v, u - 2: u + 3].sum()
        assert (dx[v, u], dy[v, u]) == (exp_dx, exp_dy)


def test_usurf_unit_and_invariant_to_gain_and_offset(textured):
    img = textured(120, 160, seed=1)
    xy = np.array([[60.0, 50.0], [100.0, 70.0], [80.0, 60.0]])
    d = usurf(img, xy, 1.2)
    assert d.shape == (3, 64) and d.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-6)
    brighter = (img.astype(np.int32) // 2 + 60).astype(np.uint8)
    np.testing.assert_allclose(usurf(brighter, xy, 1.2), d, atol=0.02)  # only integer rounding
    # a vertical step edge: only x responses, all of one sign
    edge = np.zeros((80, 80), np.uint8)
    edge[:, 40:] = 200
    e = usurf(edge, np.array([[40.0, 40.0]]), 1.2)[0].reshape(16, 4)
    assert np.all(e[:, 2:] == 0) and np.all(e[:, 0] >= 0) and e[:, 0].sum() > 0.5


def _corners_found(kps, squares) -> list[int]:
    """How many of each square's (x0, y0, x1, y1) 4 corners have a keypoint within 1.5 px."""
    found = []
    for x0, y0, x1, y1 in squares:
        corners = np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1]], float) - 0.5
        d = np.linalg.norm(kps.xy[:, None] - corners[None], axis=2)
        found.append(int((d.min(axis=0) <= 1.5).sum()))
    return found


def test_one_threshold_for_the_image_keeps_the_strongest_squares_corners_only():
    """A white square on black in the left half, a square 40 grey levels above its background in
    the right half. Harris grows with contrast^4 ((40/255)^4 = 6e-4 of the strongest): one threshold
    for the image (1 % of its strongest) keeps only the white square's corners."""
    img = np.zeros((60, 120), np.uint8)
    img[:, 60:] = 100
    img[20:40, 20:40] = 255
    img[20:40, 80:100] = 140
    squares = [(20, 20, 40, 40), (80, 20, 100, 40)]
    image_wide = harris(img, FrontendConfig(grid_cols=2, grid_rows=1), margin=5)
    assert _corners_found(image_wide, squares) == [4, 0] and len(image_wide) == 4


def _track(tr: Tracker, xy: np.ndarray, desc: np.ndarray, window=None) -> tuple[np.ndarray, np.ndarray]:
    """One frame through the tracker: match in the window, then commit (no 3D points needed)."""
    prev = tr.match(xy, desc, window)
    n = xy.shape[0]
    return tr.commit(xy, desc, np.zeros((n, 3)), np.zeros((n, 3, 3)), prev)


def test_tracker_keeps_ids_and_counts_consecutive_frames():
    rng = np.random.default_rng(2)
    desc = rng.standard_normal((5, 64)).astype(np.float32)
    desc /= np.linalg.norm(desc, axis=1, keepdims=True)
    xy = rng.uniform(0, 300, (5, 2))
    tr = Tracker(FrontendConfig())
    ids0, _ = _track(tr, xy, desc)
    ids1, len1 = _track(tr, xy + 3.0, desc)
    np.testing.assert_array_equal(ids1, ids0)
    np.testing.assert_array_equal(len1, 2)
    ids2, len2 = _track(tr, (xy + 200.0)[:2], desc[:2])  # jumped beyond track_radius_px: new tracks
    assert set(ids2).isdisjoint(ids0) and np.all(len2 == 1)


def test_tracker_follows_the_common_image_motion_of_a_turning_robot():
    # a turn moves every point by about f·ω/rate (here 100 px to the left), beyond track_radius_px
    rng = np.random.default_rng(3)
    desc = rng.standard_normal((12, 64)).astype(np.float32)
    desc /= np.linalg.norm(desc, axis=1, keepdims=True)
    xy = np.column_stack([rng.uniform(120, 300, 12), rng.uniform(10, 230, 12)])
    moved = xy + [-100.0, 2.0] + rng.normal(0, 1.0, (12, 2))
    tr = Tracker(FrontendConfig())
    ids0, _ = _track(tr, xy, desc)
    ids1, len1 = _track(tr, moved, desc)
    np.testing.assert_array_equal(ids1, ids0)
    np.testing.assert_array_equal(len1, 2)
    np.testing.assert_allclose(tr.shift, [-100.0, 2.0], atol=1.5)
    fixed = Tracker(FrontendConfig(track_search_px=0.0))  # gate around the old position only
    ids0, _ = _track(fixed, xy, desc)
    ids1, len1 = _track(fixed, moved, desc)
    assert set(ids1).isdisjoint(ids0) and np.all(len1 == 1)


def test_tracker_searches_where_the_predicted_motion_puts_each_point():
    # a car's forward motion spreads the image out from the centre: no common shift, and points
    # near the edge move 40+ px; the window sits at each point's predicted pixel
    rng = np.random.default_rng(6)
    desc = rng.standard_normal((10, 64)).astype(np.float32)
    desc /= np.linalg.norm(desc, axis=1, keepdims=True)
    xy = np.column_stack([rng.uniform(20, 300, 10), rng.uniform(20, 220, 10)])
    expanded = 160 + 1.5 * (xy - 160)  # moved from the centre, up to 70 px
    cov = np.broadcast_to(4.0 * np.eye(2), (10, 2, 2))
    tr = Tracker(FrontendConfig())
    ids0, _ = _track(tr, xy, desc)
    ids1, len1 = _track(tr, expanded + 1.0, desc, (expanded, cov, np.ones(10, bool)))
    np.testing.assert_array_equal(ids1, ids0)
    tr2 = Tracker(FrontendConfig())
    ids0, _ = _track(tr2, xy, desc)
    usable = np.arange(10) != 4  # behind the camera: not searched
    wrong = expanded.copy()
    wrong[3] += [5.0, 0.0]  # 2.5 sigma off: outside the 99 % gate (3.03 sigma) only with less noise
    wrong[5] += [7.0, 0.0]  # 3.5 sigma: outside
    ids1, len1 = _track(tr2, expanded, desc, (wrong, cov, usable))
    assert list(np.flatnonzero(len1 == 1)) == [4, 5]


def test_select_spread_takes_one_per_cell_first():
    xy = np.array([[10, 10], [12, 12], [14, 10], [300, 200], [310, 210]], float)
    strength = np.array([5.0, 4.0, 3.0, 1.0, 0.5])
    pick = select_spread(xy, strength, np.ones(5, bool), 2, 320, 240, 2, 2)
    np.testing.assert_array_equal(pick, [0, 3])  # strongest of each occupied cell
    pick = select_spread(xy, strength, np.array([1, 1, 1, 0, 1], bool), 3, 320, 240, 2, 2)
    np.testing.assert_array_equal(pick, [0, 4, 1])


def test_scan_bins_obstacles_and_free_space():
    cfg = FrontendConfig(scan_bins=4, scan_max_range=5.0)
    pts = np.array([
        [2.0, 0.1, 0.5],    # obstacle, bearing +0.05 rad -> bin 2 of [-0.4, 0.4)
        [3.0, 0.15, 0.5],   # farther obstacle in the same bin
        [1.0, -0.3, 0.0],   # floor, bearing -0.29 -> bin 0
        [4.0, 0.0, 3.0],    # above the band: ignored
        [9.0, 0.0, 0.5],    # beyond range
    ])
    scan = scan_from_points(pts, 7, -0.4, 0.4, cfg)
    assert scan.angle_increment == pytest.approx(0.2)
    assert scan.ranges[2] == pytest.approx(np.hypot(2.0, 0.1))
    assert np.isinf(scan.ranges[[0, 1, 3]]).all()
    assert scan.free_ranges[0] == pytest.approx(np.hypot(1.0, 0.3))
    assert scan.free_ranges[2] == 0.0
    np.testing.assert_allclose(scan.points, [[2.0, 0.1], [3.0, 0.15]])


def test_config_roundtrip_and_validation():
    cfg = from_dict(FrontendConfig, {"detector": "orb", "max_observations": 8})
    assert from_dict(FrontendConfig, to_dict(cfg)) == cfg
    with pytest.raises(ConfigError):
        from_dict(FrontendConfig, {"detector": "surf"})
    with pytest.raises(ConfigError):
        from_dict(FrontendConfig, {"min_disparity": 70, "max_disparity": 64})


@pytest.fixture
def frontend_and_pair(small_rig, textured):
    img = textured(240, 340, seed=5)
    return Frontend(small_rig, FrontendConfig(max_disparity=32)), (
        np.ascontiguousarray(img[:, :320]), np.ascontiguousarray(img[:, 10:330]))


@pytest.mark.parametrize(
    "make, kwargs, reason",
    [
        (lambda l, r: (l[:0], r), {}, "empty"),
        (lambda l, r: (l, r[:, :300]), {}, "size_mismatch"),
        (lambda l, r: (l[:200], r[:200]), {}, "size_mismatch"),
        (lambda l, r: (l, np.dstack([r] * 3)), {}, "encoding_mismatch"),
        (lambda l, r: (l.astype(np.float32), r), {}, "unsupported_dtype"),
        (lambda l, r: (l, r), {"encoding": "rgb8"}, "encoding_mismatch"),
        (lambda l, r: (l, r), {"encoding": "yuv422"}, "unsupported_encoding"),
        (lambda l, r: (np.full_like(l, 255), r), {}, "saturated"),
        (lambda l, r: (np.zeros_like(l), r), {}, "saturated"),
        (lambda l, r: (l, r), {"right_stamp_ns": 10**9 + 50_000_000}, "stamp_skew"),
        (lambda l, r: ("not an image", r), {}, "not_an_array"),
    ],
)
def test_bad_input_is_a_counted_drop(frontend_and_pair, make, kwargs, reason):
    fe, (left, right) = frontend_and_pair
    out = fe.step(*make(left, right), 10**9, **kwargs)
    assert out == (None, None)
    assert fe.drops == {reason: 1}
    obs, scan = fe.step(left, right, 2 * 10**9)  # recovers on the next good pair
    assert obs is not None and scan is not None and fe.frames == 1


def test_colour_and_16bit_pairs_are_converted(frontend_and_pair):
    fe, (left, right) = frontend_and_pair
    obs, _ = fe.step(np.dstack([left] * 3), np.dstack([right] * 3), 1, encoding="bgr8")
    assert obs is not None
    obs, _ = fe.step(left.astype(np.uint16) << 8, right.astype(np.uint16) << 8, 2)
    assert obs is not None and not fe.drops
    assert fe.step(left, right, 2) == (None, None) and fe.drops == {"stamp_out_of_order": 1}


def test_a_gap_in_the_stream_ends_every_track(frontend_and_pair):
    """The same still pair: tracks continue from frame to frame, but not across a 2 s gap (a
    paused camera), and the visual odometry takes no motion over it."""
    fe, (left, right) = frontend_and_pair
    for stamp in (0, 200_000_000, 400_000_000):
        fe.step(left, right, stamp)
    before = set(fe.last_frame.track_ids)
    assert fe.last_frame.track_length.max() == 3 and fe.track_gaps == 0
    fe.step(left, right, 2_400_000_000)
    assert fe.track_gaps == 1 and set(fe.last_frame.track_ids).isdisjoint(before)
    assert np.all(fe.last_frame.track_length == 1) and fe.vo_failures == 0
    np.testing.assert_allclose(fe.odometry.pose, np.eye(4), atol=1e-9)
    fe.step(left, right, 2_600_000_000)  # and tracks again from there
    assert fe.last_frame.track_length.max() == 2
