"""The one ``main`` every node module shares: init, spin until Ctrl-C or shutdown, clean up."""

from __future__ import annotations

import faulthandler
import signal
import sys
import traceback
from collections.abc import Callable

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node


def run_node(make: Callable[[], Node], argv: list[str] | None = None, threads: int = 1) -> int:
    """Create the node with ``make`` after ``rclpy.init(argv)`` and spin it (with a multi-threaded
    executor of ``threads`` threads when > 1, for nodes with several callback groups); returns 0."""
    rclpy.init(args=argv if argv is not None else sys.argv)
    # A node that a launcher's SIGINT did not stop gets SIGTERM: print where every thread is
    # (into the node's log) before rclpy's own handler runs, so a hang names its cause.
    faulthandler.register(signal.SIGTERM, all_threads=True, chain=True)
    node = make()
    try:
        if threads > 1:
            from rclpy.executors import MultiThreadedExecutor

            executor = MultiThreadedExecutor(num_threads=threads)
            executor.add_node(node)
            executor.spin()
        else:
            executor = SingleThreadedExecutor()
            executor.add_node(node)
            while executor.context.ok():
                try:
                    executor.spin_once()
                except RuntimeError as exc:
                    if not failed_take(exc):
                        raise
                    drop_untakeable(node, exc)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def drop_untakeable(node: Node, exc: BaseException) -> None:
    """Log and count (``untakeable_message`` on the node's ``diag``, if it has one) a message the
    middleware handed over but rclpy could not convert, seen after a process was stopped (SIGSTOP)
    for 30 s, under heavy load and across network namespaces; the caller drops it and goes on."""
    node.get_logger().error(f"dropped a message that could not be taken: {exc}")
    diag = getattr(node, "diag", None)
    if diag is not None:
        diag.count("untakeable_message", str(exc))


def failed_take(exc: BaseException) -> bool:
    """Whether ``exc`` was raised while rclpy took a message from a subscription (not in a callback)."""
    return any(frame.name == "_take_subscription" for frame in traceback.extract_tb(exc.__traceback__))
