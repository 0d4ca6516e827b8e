"""run_node, and the central node's own drain of its inputs, keep going past a message the middleware
cannot hand over, and only past that; a node process's teardown bounds the middleware's part."""

import subprocess
import sys
import time

import pytest

pytestmark = pytest.mark.ros


def _take_subscription():  # the name of rclpy's executor frame that takes a message
    raise RuntimeError("Unable to convert call argument '0' to Python object")


def _callback():
    raise RuntimeError("a bug in a callback")


def test_failed_take_is_told_apart_from_a_failing_callback():
    from mrslam_ros.spin import failed_take

    for fn, want in ((_take_subscription, True), (_callback, False)):
        with pytest.raises(RuntimeError) as info:
            fn()
        assert failed_take(info.value) is want


class _Handle:
    """A subscription handle whose takes return the given items in turn (an exception is raised)."""

    def __init__(self, *items):
        self.items = list(items)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def take_message(self, msg_type, raw):
        item = self.items.pop(0) if self.items else None
        if isinstance(item, Exception):
            raise item
        return item


def test_the_central_node_counts_an_untakeable_input_and_drains_the_others():
    from types import SimpleNamespace

    from mrslam_ros.slam_node import SlamNode

    got, counted, logged = [], [], []
    bad = RuntimeError("Unable to convert call argument '0' to Python object")

    def sub(*items):
        return SimpleNamespace(handle=_Handle(*items), msg_type=None, raw=False, callback=got.append)

    node = SimpleNamespace(
        inputs=[sub(("a1", None), bad, ("a2", None)), None, sub(("b1", None), ("b2", None))],
        cfg=SimpleNamespace(input_depth=10),
        diag=SimpleNamespace(count=lambda reason, detail="": counted.append((reason, detail))),
        get_logger=lambda: SimpleNamespace(error=logged.append),
    )
    SlamNode.drain(node)
    assert got == ["a1", "b1", "b2"]  # the first input's later message waits for the next drain
    assert counted == [("untakeable_message", str(bad))] and len(logged) == 1
    SlamNode.drain(node)
    assert got == ["a1", "b1", "b2", "a2"]


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


BUSY = """
import sys, time
from rclpy.node import Node
from mrslam_ros.spin import run_node

class Busy(Node):
    def __init__(self):
        super().__init__("busy")
        self.create_timer(0.01, self.work)

    def work(self):
        print("begin", flush=True)
        time.sleep(float(sys.argv[1]))
        print("end", flush=True)

    def destroy_node(self):
        print("destroyed", flush=True)
        super().destroy_node()

sys.exit(run_node(Busy, []))
"""


def _interrupt(seconds: float, signals: list) -> tuple[subprocess.CompletedProcess, float]:
    """Start the busy node (its first callback sleeps ``seconds``), send ``signals`` 0.3 s apart
    once the callback began; the process result and the wall time from the first signal."""
    proc = subprocess.Popen([sys.executable, "-c", BUSY, str(seconds)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "begin"
    start = time.monotonic()
    for sig in signals:
        proc.send_signal(sig)
        time.sleep(0.3)
    out, err = proc.communicate(timeout=30)
    return subprocess.CompletedProcess(proc.args, proc.returncode, "begin\n" + out, err), time.monotonic() - start


def test_a_stop_signal_lets_the_running_callback_finish_before_the_teardown():
    import signal

    for sig in (signal.SIGINT, signal.SIGTERM):
        proc, _ = _interrupt(1.5, [sig])
        assert proc.returncode == 0, proc.stderr
        assert proc.stdout.split() == ["begin", "end", "destroyed"], proc.stdout
        assert "did not finish" not in proc.stderr, proc.stderr  # the executor let go of the node


def test_a_second_signal_interrupts_a_hung_callback():
    import signal

    proc, wall = _interrupt(60.0, [signal.SIGINT, signal.SIGTERM])
    assert proc.returncode == 0 and wall < 10, (proc.returncode, wall, proc.stderr)
    assert proc.stdout.split() == ["begin", "destroyed"], proc.stdout
    assert "time.sleep" in proc.stderr or "work" in proc.stderr  # faulthandler: where it hung
