"""run_node keeps spinning past a message the middleware cannot hand over, and only past that."""

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
