"""ROS graph tests: a private DDS domain per test session, localhost only."""

import os
import random

import pytest

rclpy = pytest.importorskip("rclpy", reason="rclpy (the `ros` extra) is not installed")


@pytest.fixture(scope="session", autouse=True)
def ros_domain():
    os.environ["ROS_DOMAIN_ID"] = str(random.Random(os.getpid()).randint(30, 200))
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    yield
