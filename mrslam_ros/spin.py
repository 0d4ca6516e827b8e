"""The one ``main`` every node module shares: init, spin until Ctrl-C or shutdown, clean up."""

from __future__ import annotations

import sys
from collections.abc import Callable

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node


def run_node(make: Callable[[], Node], argv: list[str] | None = None, threads: int = 1) -> int:
    """Create the node with ``make`` after ``rclpy.init(argv)`` and spin it (with a multi-threaded
    executor of ``threads`` threads when > 1, for nodes with several callback groups); returns 0."""
    rclpy.init(args=argv if argv is not None else sys.argv)
    node = make()
    try:
        if threads > 1:
            from rclpy.executors import MultiThreadedExecutor

            executor = MultiThreadedExecutor(num_threads=threads)
            executor.add_node(node)
            executor.spin()
        else:
            rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0
