"""ROS graph tests: a private DDS domain per test module, localhost only.

Per module, not per session: a publisher an earlier module left running on the same topic names
would otherwise feed this module's nodes (the looping bag replay's live node left its offline
reference by 0.11 m after the whole suite, and matched it to 6.7e-7 m in a domain of its own).
"""

import itertools
import os
import random

import pytest

rclpy = pytest.importorskip("rclpy", reason="rclpy (the `ros` extra) is not installed")

_FIRST = random.Random(os.getpid()).randint(30, 200)
_NEXT = itertools.count()


@pytest.fixture(scope="module", autouse=True)
def ros_domain():
    os.environ["ROS_DOMAIN_ID"] = str(30 + (_FIRST - 30 + next(_NEXT)) % 171)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    yield
