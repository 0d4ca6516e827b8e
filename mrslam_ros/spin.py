"""The one ``main`` every node module shares: init, spin until Ctrl-C or shutdown, clean up."""

from __future__ import annotations

import sys
from collections.abc import Callable

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node


def run_node(make: Callable[[], Node], argv: list[str] | None = None) -> int:
    """Create the node with ``make`` after ``rclpy.init(argv)`` and spin it; returns 0."""
    rclpy.init(args=argv if argv is not None else sys.argv)
    node = make()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0
