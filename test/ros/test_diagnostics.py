"""Counted drops reach /diagnostics from a live node."""

import time

import pytest

pytestmark = pytest.mark.ros


def test_diagnostics_are_published():
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from rclpy.executors import SingleThreadedExecutor

    from mrslam_ros.conversions import diagnostics_to_counters
    from mrslam_ros.diagnostics import Diagnostics

    rclpy.init()
    try:
        node = rclpy.create_node("diag_node", namespace="robot3")
        listener = rclpy.create_node("diag_listener")
        ex = SingleThreadedExecutor()
        ex.add_node(node)
        ex.add_node(listener)
        got = []
        listener.create_subscription(DiagnosticArray, "/diagnostics", got.append, 10)
        diag = Diagnostics(node, period=0.2)
        diag.count("wrong_frame", "robot9/base_link")
        diag.count("wrong_frame")
        diag.set("queue", 3)
        end = time.monotonic() + 5
        while time.monotonic() < end and len(got) < 2:
            ex.spin_once(timeout_sec=0.05)
        assert len(got) >= 2
        first, second = got[0].status[0], got[1].status[0]
        assert first.name == "/robot3/diag_node" and first.level == DiagnosticStatus.WARN
        assert diagnostics_to_counters(got[0])["/robot3/diag_node"] == {"drops.wrong_frame": 2.0, "drops.total": 2.0,
                                                                        "queue": 3.0}
        assert second.level == DiagnosticStatus.OK  # no new drops in the second period
        node.destroy_node()
        listener.destroy_node()
    finally:
        rclpy.shutdown()
