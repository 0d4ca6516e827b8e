"""The one ``main`` every node module shares: init, spin until Ctrl-C or shutdown, clean up."""

from __future__ import annotations

import faulthandler
import os
import signal
import sys
import threading
import traceback
from collections.abc import Callable

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions


#: longest a stop request waits for the executor to look at it [s]
STOP_POLL = 0.1


def run_node(make: Callable[[], Node], argv: list[str] | None = None) -> int:
    """Create the node with ``make`` after ``rclpy.init(argv)`` and spin it on one thread until
    a stop is requested or the context shuts down; returns 0.

    SIGINT and SIGTERM request a stop that the spin loop takes between callbacks, so a callback
    always runs to its end: an interrupt raised inside an update would leave the map half-updated
    before the node writes its checkpoint and outputs, and inside compiled (numba) code it surfaces
    as a ``SystemError`` instead of a ``KeyboardInterrupt``. A second signal while the stop is
    pending interrupts at once (a hung callback; the launcher's SIGTERM after its SIGINT).
    """
    rclpy.init(args=argv if argv is not None else sys.argv, signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()

    def request_stop(signum: int, frame: object) -> None:
        if stop.is_set():
            raise KeyboardInterrupt
        stop.set()

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, request_stop)
    # A node that did not stop after the first signal gets a second: print where every thread is
    # (into the node's log) before the interrupt, so a hang names its cause.
    faulthandler.register(signal.SIGTERM, all_threads=True, chain=True)
    node = make()
    executor = SingleThreadedExecutor()
    try:
        executor.add_node(node)
        while executor.context.ok() and not stop.is_set():
            try:
                executor.spin_once(timeout_sec=STOP_POLL)
            except RuntimeError as exc:
                if not failed_take(exc):
                    raise
                drop_untakeable(node, exc)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        # The executor's paused wait generator holds the node's handles "in use"; until it is
        # dropped, rcl's destroy of the node waits for them (an interrupt used to close it).
        executor.shutdown(timeout_sec=0)
        teardown(node)
    return 0


#: longest the middleware may take to release a node once the node's own cleanup is done [s]
#: (below the launcher's 5 s between SIGINT and SIGTERM)
TEARDOWN_TIMEOUT = 2.0


def teardown(node: Node, timeout: float = TEARDOWN_TIMEOUT) -> None:
    """``node.destroy_node()`` and ``rclpy.try_shutdown()``, with the middleware's part bounded.

    A node's own cleanup (its ``destroy_node`` override: a checkpoint, outputs, the simulator)
    runs to its end. rclpy's part (``Node.destroy_node``: handles, then the rcl node) and the
    context's shutdown run in a worker thread each, waited for ``timeout`` s: in CI runs a frontend
    stopped by SIGINT hung in ``destroy_when_not_in_use`` of its rcl node until the launcher's
    SIGKILL (its stack, printed on SIGTERM, ended there). A release that does not come in time is
    logged with every thread's stack and the process exits 0: its work is done, and the operating
    system frees what the middleware held.
    """
    base = Node.destroy_node
    name = node.get_name()

    def bounded(self: Node) -> None:
        if self is not node:
            return base(self)
        _within(lambda: base(self), timeout, f"{name}: releasing the node")

    Node.destroy_node = bounded
    try:
        node.destroy_node()
    finally:
        Node.destroy_node = base
    _within(rclpy.try_shutdown, timeout, f"{name}: shutting rclpy down")


def _within(work: Callable[[], object], timeout: float, what: str) -> None:
    """Run ``work`` in a daemon thread; if it has not returned after ``timeout`` s, log ``what``
    with every thread's stack to stderr and end the process (exit code 0)."""
    worker = threading.Thread(target=work, daemon=True, name="teardown")
    worker.start()
    worker.join(timeout)
    if worker.is_alive():
        sys.stderr.write(f"{what} did not finish within {timeout:.1f} s; exiting without it\n")
        sys.stderr.flush()
        faulthandler.dump_traceback(all_threads=True)
        os._exit(0)


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
