"""A node process's teardown: the middleware's part is bounded (mrslam_ros/spin.py)."""

import subprocess
import sys
import time

import pytest

pytestmark = pytest.mark.ros

HUNG = """
import sys, time
from mrslam_ros.spin import _within
_within(lambda: time.sleep(60), 0.5, "releasing the node")
print("not reached")
"""

CLEAN = """
import rclpy
from rclpy.node import Node
from mrslam_ros.spin import teardown
rclpy.init()
node = Node("teardown_check")
teardown(node)
print("released", rclpy.ok())
"""


def test_a_teardown_that_hangs_ends_the_process_cleanly_and_says_where():
    start = time.monotonic()
    proc = subprocess.run([sys.executable, "-c", HUNG], capture_output=True, text=True, timeout=30)
    assert proc.returncode == 0 and time.monotonic() - start < 10
    assert "releasing the node did not finish within 0.5 s" in proc.stderr and "not reached" not in proc.stdout
    assert "time.sleep" in proc.stderr or "<lambda>" in proc.stderr  # the stack of the hung worker


def test_a_node_is_released_and_rclpy_shut_down():
    proc = subprocess.run([sys.executable, "-c", CLEAN], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and "released False" in proc.stdout, proc.stderr
