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

# Under pytest-xdist (`make test`) each worker takes its own share of the domains 30-199, so two
# workers' modules never share one; within the share, a random start per process.
_WORKER = int(os.environ.get("PYTEST_XDIST_WORKER", "gw0")[2:])
_SHARES = max(1, int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")))
_SPAN = 170 // _SHARES
_BASE = 30 + _WORKER * _SPAN
_FIRST = random.Random(os.getpid()).randrange(_SPAN)
_NEXT = itertools.count()


@pytest.fixture(scope="module", autouse=True)
def ros_domain():
    os.environ["ROS_DOMAIN_ID"] = str(_BASE + (_FIRST + next(_NEXT)) % _SPAN)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    yield
