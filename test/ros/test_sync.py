"""Approximate-time synchroniser: exact cases by hand, invariants by hypothesis; no graph."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mrslam_ros.sync import ApproximateTimeSync, StereoSync

MS = 1_000_000


def test_pairs_within_slop_and_counts_drops():
    sync = ApproximateTimeSync(2, slop_ns=3 * MS, queue_size=3)
    assert sync.add(0, 100 * MS, "L100") is None
    assert sync.add(1, 110 * MS, "R110") is None  # 10 ms apart: no pair
    assert sync.add(0, 111 * MS, "L111") == ["L111", "R110"]  # 1 ms apart
    # L100 was older than the emitted L111: it can never be emitted
    assert sync.drops["unmatched"] == 1 and sync.queued() == [0, 0]
    assert sync.add(1, 105 * MS, "R105") is None and sync.drops["late"] == 1  # before the last emitted R110
    assert sync.add(0, 120 * MS, "L120") is None
    assert sync.add(0, 120 * MS, "L120bis") is None and sync.drops["duplicate"] == 1
    for t in (130, 140, 150):  # right never comes: the queue (3) overflows once
        sync.add(0, t * MS, f"L{t}")
    assert sync.drops["overflow"] == 1 and sync.queued() == [3, 0]
    assert sync.add(1, 141 * MS, "R141") == ["L140", "R141"]
    assert sync.drops["unmatched"] == 1 + 1 and sync.queued() == [1, 0]  # L130 gone, L150 waits
    assert sync.emitted == 2


def test_picks_the_nearest_partner_not_the_first():
    sync = ApproximateTimeSync(2, slop_ns=10 * MS)
    sync.add(0, 100 * MS, "a")
    sync.add(0, 104 * MS, "b")
    assert sync.add(1, 105 * MS, "r") == ["b", "r"]
    assert sync.drops["unmatched"] == 1


def test_out_of_order_arrivals_still_pair():
    sync = ApproximateTimeSync(2, slop_ns=0)
    sync.add(0, 20 * MS, "L20")
    sync.add(0, 10 * MS, "L10")  # arrives late but nothing at 10 ms was emitted yet
    assert sync.add(1, 10 * MS, "R10") == ["L10", "R10"]
    assert sync.add(1, 20 * MS, "R20") == ["L20", "R20"]
    assert sum(sync.drops.values()) == 0


def test_bad_arguments():
    with pytest.raises(ValueError):
        ApproximateTimeSync(0, 1)
    with pytest.raises(ValueError):
        ApproximateTimeSync(2, -1)
    with pytest.raises(IndexError):
        ApproximateTimeSync(2, 1).add(2, 0, None)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 2), st.integers(0, 60)), max_size=80),
       st.integers(0, 5), st.integers(1, 4))
def test_invariants(events, slop, queue):
    """Every offered message is emitted once, dropped once, or still queued; sets are within slop
    and in increasing stamp order per stream."""
    sync = ApproximateTimeSync(3, slop, queue)
    sets = []
    for i, (stream, t) in enumerate(events):
        out = sync.add(stream, t, (stream, t, i))
        if out is not None:
            sets.append(out)
    for s in sets:
        stamps = [m[1] for m in s]
        assert [m[0] for m in s] == [0, 1, 2]
        assert max(stamps) - min(stamps) <= slop
    for k in range(3):
        per_stream = [s[k][1] for s in sets]
        assert per_stream == sorted(set(per_stream))
    ids = [m[2] for s in sets for m in s]
    assert len(ids) == len(set(ids))
    assert len(ids) + sum(sync.drops.values()) + sum(sync.queued()) == len(events)


def _header(msg, ns):
    msg.header.stamp.sec, msg.header.stamp.nanosec = ns // 10**9, ns % 10**9
    return msg


def test_stereo_sync_with_messages():
    pytest.importorskip("sensor_msgs")
    from sensor_msgs.msg import CameraInfo, Image

    frames = []
    sync = StereoSync(frames.append, slop_ns=2 * MS, queue_size=4)
    t = 5 * 10**9
    sync.left_info(_header(CameraInfo(width=320), t))
    sync.left_image(_header(Image(width=320), t))
    sync.right_image(_header(Image(width=321), t + 1 * MS))
    assert not frames  # right camera_info still missing
    sync.right_info(_header(CameraInfo(width=321), t + 1 * MS))
    assert len(frames) == 1
    f = frames[0]
    assert f.stamp_ns == t and f.left.width == 320 and f.right.width == 321 and f.right_info.width == 321
    # a right image 3 ms off never pairs; the next good frame does and the stale one is counted
    sync.right_image(_header(Image(), t + 100 * MS))
    for fn, dt in ((sync.left_image, 97), (sync.left_info, 97), (sync.right_info, 97)):
        fn(_header(Image() if fn == sync.left_image else CameraInfo(), t + dt * MS))
    assert len(frames) == 1
    for fn, dt in ((sync.left_image, 200), (sync.left_info, 200), (sync.right_info, 200), (sync.right_image, 200)):
        fn(_header(Image() if "image" in fn.__name__ else CameraInfo(), t + dt * MS))
    assert len(frames) == 2 and frames[1].stamp_ns == t + 200 * MS
    assert sync.drops["unmatched"] == 4
