"""run_node, and the central node's own drain of its inputs, keep going past a message the middleware
cannot hand over, and only past that."""

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
