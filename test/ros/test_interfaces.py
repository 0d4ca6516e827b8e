"""The generated tf2_msgs works on a real graph: /tf across processes, /tf_static latched."""

import subprocess
import sys
import textwrap
import time

import pytest

pytestmark = pytest.mark.ros

PUBLISHER = textwrap.dedent(
    """
    import sys, time, rclpy
    from rclpy.qos import QoSProfile, DurabilityPolicy
    from tf2_msgs.msg import TFMessage
    from geometry_msgs.msg import TransformStamped
    rclpy.init()
    node = rclpy.create_node("tf_pub")
    topic, latched = sys.argv[1], sys.argv[2] == "1"
    qos = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)
    pub = node.create_publisher(TFMessage, topic, qos)
    t = TransformStamped()
    t.header.frame_id, t.child_frame_id = "map", "robot1/odom"
    t.transform.translation.x = 1.5
    t.transform.rotation.w = 1.0
    end = time.time() + float(sys.argv[3])
    sent = False
    while time.time() < end:
        if not latched or not sent:
            pub.publish(TFMessage(transforms=[t]))
            sent = True
        rclpy.spin_once(node, timeout_sec=0.1)
    """
)


def _receive(topic: str, latched: bool, publisher_seconds: float, subscribe_after: float) -> list:
    import rclpy
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from tf2_msgs.msg import TFMessage

    proc = subprocess.Popen([sys.executable, "-c", PUBLISHER, topic, "1" if latched else "0", str(publisher_seconds)])
    try:
        time.sleep(subscribe_after)
        rclpy.init()
        node = rclpy.create_node("tf_sub")
        got = []
        qos = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)
        node.create_subscription(TFMessage, topic, got.append, qos)
        end = time.time() + publisher_seconds
        while time.time() < end and not got:
            rclpy.spin_once(node, timeout_sec=0.1)
        node.destroy_node()
        rclpy.shutdown()
        return got
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def test_tf_round_trip_between_processes():
    got = _receive("/tf", latched=False, publisher_seconds=8.0, subscribe_after=0.0)
    assert got and got[0].transforms[0].child_frame_id == "robot1/odom"
    assert got[0].transforms[0].transform.translation.x == 1.5


def test_tf_static_reaches_a_late_subscriber():
    # published once, 2 s before anyone listens: transient-local durability must deliver it
    got = _receive("/tf_static", latched=True, publisher_seconds=8.0, subscribe_after=2.0)
    assert len(got) == 1 and got[0].transforms[0].header.frame_id == "map"
