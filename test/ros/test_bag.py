"""rosbag2 record and replay: tiny bags written with rosbags in tmp_path, both storages.

The first tests need no graph; the ``ros`` ones record from and play into a live graph.
"""

from __future__ import annotations

import itertools
import os
import subprocess
import sys
import time

import numpy as np
import pytest

from mrslam_ros.bag import (
    BagError,
    BagMessage,
    bag_info,
    deserialize,
    read_bag,
    serialize,
    typestore,
    write_bag,
)

STORAGES = ["sqlite3", "mcap"]
T0 = 1_700_000_000_000_000_000  # a bag's first log time [ns]


def _image(ts, stamp_ns: int, value: int):
    Image, Header, Time = (ts.types[n] for n in ("sensor_msgs/msg/Image", "std_msgs/msg/Header",
                                                  "builtin_interfaces/msg/Time"))
    header = Header(stamp=Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), frame_id="robot1/camera_left")
    data = np.full(6 * 4, value, np.uint8)
    return Image(header=header, height=4, width=6, encoding="mono8", is_bigendian=0, step=6, data=data)


def _tf(ts, x: float):
    T = ts.types
    Header, Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    tr = T["geometry_msgs/msg/Transform"](translation=T["geometry_msgs/msg/Vector3"](x=x, y=0.0, z=0.0),
                                          rotation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
    st = T["geometry_msgs/msg/TransformStamped"](header=Header(stamp=Time(sec=0, nanosec=0), frame_id="map"),
                                                 child_frame_id="robot1/odom", transform=tr)
    return T["tf2_msgs/msg/TFMessage"](transforms=[st])


def make_bag(path, storage: str, n: int = 6, period_ns: int = 200_000_000):
    """n mono8 images (pixel value = index) every period_ns on /robot1/image and one /tf."""
    ts = typestore()
    msgs = [BagMessage("/robot1/image", "sensor_msgs/msg/Image", T0 + i * period_ns,
                       serialize(_image(ts, T0 + i * period_ns, i), "sensor_msgs/msg/Image")) for i in range(n)]
    msgs.insert(1, BagMessage("/tf", "tf2_msgs/msg/TFMessage", T0 + 1, serialize(_tf(ts, 1.5), "tf2_msgs/msg/TFMessage")))
    return write_bag(path, msgs, storage)


@pytest.mark.parametrize("storage", STORAGES)
def test_write_read_round_trip(tmp_path, storage):
    bag = make_bag(tmp_path / "bag", storage)
    info = bag_info(bag)
    assert info.storage == storage
    assert info.topics["/robot1/image"].count == 6 and info.topics["/tf"].msgtype == "tf2_msgs/msg/TFMessage"
    assert info.start_ns == T0 and info.end_ns == T0 + 5 * 200_000_000
    assert info.duration_s == pytest.approx(1.0)
    msgs = list(read_bag(bag))
    assert [m.stamp_ns for m in msgs] == sorted(m.stamp_ns for m in msgs)
    images = [deserialize(m.data, m.msgtype) for m in msgs if m.topic == "/robot1/image"]
    assert [int(im.data[0]) for im in images] == list(range(6))
    assert images[3].header.stamp.sec == (T0 + 600_000_000) // 10**9
    only_tf = list(read_bag(bag, ["/tf"]))
    assert len(only_tf) == 1 and deserialize(only_tf[0].data, only_tf[0].msgtype).transforms[0].transform.translation.x == 1.5


def test_bad_bags(tmp_path):
    with pytest.raises(BagError, match="not a rosbag2"):
        bag_info(tmp_path)
    with pytest.raises(BagError, match="not in the ROS 2 Jazzy typestore"):
        write_bag(tmp_path / "b1", [BagMessage("/x", "my_msgs/msg/Nope", 1, b"\x00\x01\x00\x00")])
    make_bag(tmp_path / "b2", "sqlite3")
    with pytest.raises(BagError, match="exists"):
        make_bag(tmp_path / "b2", "sqlite3")
    with pytest.raises(BagError, match="unknown bag storage"):
        make_bag(tmp_path / "b3", "rosbag1")


def test_rclpy_reads_rosbags_cdr():
    """The bytes rosbags serializes are what rclpy publishes (same CDR, same encapsulation)."""
    rclpy_serialization = pytest.importorskip("rclpy.serialization")
    from sensor_msgs.msg import Image

    data = serialize(_image(typestore(), T0, 7), "sensor_msgs/msg/Image")
    msg = rclpy_serialization.deserialize_message(data, Image)
    assert msg.width == 6 and msg.header.frame_id == "robot1/camera_left" and bytes(msg.data)[5] == 7
    back = deserialize(rclpy_serialization.serialize_message(msg), "sensor_msgs/msg/Image")  # padding bytes may differ
    assert back.header.stamp.sec == T0 // 10**9 and back.step == 6 and bytes(back.data) == bytes(msg.data)


# ---------------------------------------------------------------------------------- live graph
def _spin_until(executor, cond, timeout: float) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end and not cond():
        executor.spin_once(timeout_sec=0.05)


@pytest.mark.ros
@pytest.mark.parametrize("storage", STORAGES)
def test_replay_publishes_with_timing_and_clock(tmp_path, storage):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import Image
    from tf2_msgs.msg import TFMessage

    bag = make_bag(tmp_path / "bag", storage, n=6, period_ns=200_000_000)
    rclpy.init()
    node = rclpy.create_node("replay_listener")
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    images, tfs, clocks = [], [], []
    node.create_subscription(Image, "/robot1/image", lambda m: images.append((time.monotonic(), m)), 50)
    node.create_subscription(TFMessage, "/tf", tfs.append, 50)
    node.create_subscription(Clock, "/clock", lambda m: clocks.append(m.clock.sec * 10**9 + m.clock.nanosec), 500)
    proc = subprocess.Popen([sys.executable, "-m", "mrslam_ros.replay", str(bag), "--rate", "2", "--wait", "10"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        _spin_until(ex, lambda: len(images) == 6 and proc.poll() is not None, 25)
    finally:
        if proc.poll() is None:
            proc.kill()
        out = proc.communicate(timeout=10)[0]
        node.destroy_node()
        rclpy.shutdown()
    assert proc.returncode == 0, out
    assert "published 7 messages" in out
    assert [bytes(m.data)[0] for _, m in images] == list(range(6))
    assert tfs and tfs[0].transforms[0].transform.translation.x == 1.5
    # the first image goes out ahead of time (the player waits for its acknowledgement); the other
    # five span 0.8 s of bag, at rate 2 0.4 s of wall time
    span = images[-1][0] - images[1][0]
    assert 0.25 < span < 0.8, span
    # /clock carries bag time: it starts at the bag's start, never passes its end, and ticks between messages
    assert clocks[0] == T0 and max(clocks) == T0 + 1_000_000_000 and len(clocks) > 15
    assert all(b >= a for a, b in itertools.pairwise(clocks))


@pytest.mark.ros
def test_replay_loop_jumps_clock_back(tmp_path):
    import rclpy

    from mrslam_ros.replay import BagPlayer

    bag = make_bag(tmp_path / "bag", "mcap", n=3, period_ns=50_000_000)
    rclpy.init()
    try:
        node = rclpy.create_node("loop_player")
        player = BagPlayer(node, bag, rate=5.0, loop=True, clock_hz=0)
        stamps = []
        player.publish_clock = stamps.append  # observe the clock the player would publish
        n = player.run(max_loops=3)
        assert n == 3 * 4 and player.loops == 3 and player.published["/robot1/image"] == 9
        backwards = sum(b < a for a, b in itertools.pairwise(stamps))
        assert backwards == 2  # once per restart
        with pytest.raises(BagError, match="not in"):
            BagPlayer(node, bag, topics=["/nope"])
        with pytest.raises(BagError, match="rate"):
            BagPlayer(node, bag, rate=0)
        node.destroy_node()
    finally:
        rclpy.shutdown()


@pytest.mark.ros
@pytest.mark.parametrize("storage", STORAGES)
def test_recorder_writes_what_the_graph_carries(tmp_path, storage):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.serialization import deserialize_message
    from rosbags.interfaces import QosDurability
    from sensor_msgs.msg import Image
    from tf2_msgs.msg import TFMessage

    from mrslam_ros.bag import BagRecorder
    from mrslam_ros.conversions import array_to_image, transform_msg
    from mrslam_ros.qos import SENSOR, TF_STATIC

    rclpy.init()
    try:
        talker = rclpy.create_node("talker")
        recorder_node = rclpy.create_node("recorder")
        ex = SingleThreadedExecutor()
        ex.add_node(talker)
        ex.add_node(recorder_node)
        static = talker.create_publisher(TFMessage, "/tf_static", TF_STATIC)
        static.publish(TFMessage(transforms=[transform_msg(np.array([0.1, 0.0, 0.0]), 0, "robot1/base_link",
                                                           "robot1/camera")]))  # before the recorder exists
        pub = talker.create_publisher(Image, "/robot1/image", SENSOR)
        rec = BagRecorder(recorder_node, tmp_path / "rec", topics=["/tf_static", "/robot1/image"], storage=storage)
        _spin_until(ex, lambda: pub.get_subscription_count() > 0 and static.get_subscription_count() > 0, 5)
        for i in range(5):
            pub.publish(array_to_image(np.full((4, 6), i, np.uint8), "mono8", i * 1000, "cam"))
            ex.spin_once(timeout_sec=0.01)
        _spin_until(ex, lambda: rec.counts["/robot1/image"] == 5 and rec.counts["/tf_static"] == 1, 5)
        rec.close()
        talker.destroy_node()
        recorder_node.destroy_node()
    finally:
        rclpy.shutdown()
    info = bag_info(tmp_path / "rec")
    assert info.storage == storage and info.topics["/robot1/image"].count == 5 and info.topics["/tf_static"].count == 1
    assert info.topics["/tf_static"].offered_qos[0].durability == QosDurability.TRANSIENT_LOCAL
    images = [deserialize_message(m.data, Image) for m in read_bag(tmp_path / "rec", ["/robot1/image"])]
    assert [bytes(m.data)[0] for m in images] == [0, 1, 2, 3, 4]
    assert [m.header.stamp.nanosec for m in images] == [0, 1000, 2000, 3000, 4000]
    tf = deserialize(next(read_bag(tmp_path / "rec", ["/tf_static"])).data, "tf2_msgs/msg/TFMessage")
    assert tf.transforms[0].child_frame_id == "robot1/camera"
    assert os.path.isfile(tmp_path / "rec" / "metadata.yaml")



@pytest.mark.ros
def test_recorder_waits_for_a_publisher_of_a_topic_seen_subscribed_first(tmp_path):
    """A viewer's subscription to /map puts the topic on the graph before its (volatile) publisher
    exists; a subscription made then with /map's latched default would never match it."""
    import rclpy
    from nav_msgs.msg import OccupancyGrid
    from rclpy.executors import SingleThreadedExecutor

    from mrslam_ros.bag import BagRecorder

    rclpy.init()
    try:
        viewer, talker, recorder_node = (rclpy.create_node(n) for n in ("viewer", "talker", "recorder"))
        ex = SingleThreadedExecutor()
        for n in (viewer, talker, recorder_node):
            ex.add_node(n)
        viewer.create_subscription(OccupancyGrid, "/map", lambda m: None, 1)
        rec = BagRecorder(recorder_node, tmp_path / "rec", topics=["/map"], storage="sqlite3", discover_period=0.05)
        _spin_until(ex, lambda: False, 0.5)  # the recorder sees /map, subscribed only
        pub = talker.create_publisher(OccupancyGrid, "/map", 1)  # volatile, as the exploration node's
        _spin_until(ex, lambda: pub.get_subscription_count() >= 2, 5)
        for _ in range(3):
            pub.publish(OccupancyGrid())
            ex.spin_once(timeout_sec=0.01)
        _spin_until(ex, lambda: rec.counts["/map"] == 3, 5)
        rec.close()
    finally:
        rclpy.shutdown()
    assert bag_info(tmp_path / "rec").topics["/map"].count == 3

def test_bag_info_cli_and_offline_hook(tmp_path, capsys):
    from mrslam_ros.bag import main as bag_main
    from mrslam_ros.replay import OFFLINE_MODULE
    from mrslam_ros.replay import main as replay_main

    bag = make_bag(tmp_path / "bag", "mcap")
    assert bag_main(["info", str(bag)]) == 0
    out = capsys.readouterr().out
    assert "mcap, 7 messages, 1.000 s" in out and "/robot1/image" in out
    assert bag_main(["info", str(tmp_path)]) == 2
    assert replay_main([str(tmp_path / "nope")]) == 2
    assert "not a rosbag2 folder" in capsys.readouterr().err
    import importlib.util

    if importlib.util.find_spec(OFFLINE_MODULE) is None:  # until the offline replay exists
        assert replay_main([str(bag), "--offline"]) == 2
        assert OFFLINE_MODULE in capsys.readouterr().err
