"""Counted drops and other counters of a node, published on /diagnostics.

Bad input never crashes a node: the node counts it (``diag.count("wrong_frame")``) and logs it at
most once per ``log_period``; the counters go out as one ``diagnostic_msgs/DiagnosticStatus`` per
node on ``/diagnostics`` every ``period`` seconds, level WARN while drops keep growing, OK otherwise.
The counting part (:class:`Counters`) has no ROS in it.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Mapping


class Counters:
    """Drop reasons and plain values of one node, with rate-limited log lines.

    Args:
        log: called with a message for the first drop of a reason and then at most once per
            ``log_period`` seconds per reason (None: no logging).
        log_period: seconds between log lines of one reason [s].
        clock: monotonic time source [s] (injectable for tests).
    """

    def __init__(self, log=None, log_period: float = 5.0, clock=time.monotonic):
        self.drops: Counter[str] = Counter()
        self.values: dict[str, float] = {}
        self._log, self._period, self._clock = log, float(log_period), clock
        self._last_log: dict[str, float] = {}
        self._published: Counter[str] = Counter()

    def count(self, reason: str, detail: str = "", n: int = 1) -> None:
        """Count ``n`` dropped inputs for ``reason`` (e.g. ``unknown_robot``); ``detail`` goes to the log."""
        self.drops[reason] += n
        now = self._clock()
        if self._log is not None and now - self._last_log.get(reason, -float("inf")) >= self._period:
            self._last_log[reason] = now
            self._log(f"dropped ({reason}, {self.drops[reason]} so far){': ' + detail if detail else ''}")

    def mirror(self, counts: Mapping[str, int], prefix: str = "", detail: str = "") -> None:
        """Count what a component's own drop counter (``counts``, reason -> total) gained since the
        last call, as ``prefix + reason``."""
        for reason, total in counts.items():
            grown = int(total) - self.drops.get(prefix + reason, 0)
            if grown > 0:
                self.count(prefix + reason, detail, grown)

    def set(self, key: str, value: float) -> None:
        """Set a plain value reported with the drops (e.g. ``update_ms_p95``)."""
        self.values[key] = float(value)

    def snapshot(self) -> tuple[dict[str, float], str, str]:
        """(all counters, level, message) for one report; level is ``warn`` when a drop count grew
        since the previous snapshot."""
        grown = sorted(k for k, v in self.drops.items() if v > self._published[k])
        self._published = Counter(self.drops)
        counters: dict[str, float] = {f"drops.{k}": float(v) for k, v in self.drops.items()}
        counters["drops.total"] = float(sum(self.drops.values()))
        counters.update(self.values)
        if grown:
            return counters, "warn", "dropping: " + ", ".join(grown)
        return counters, "ok", "ok"


class Diagnostics(Counters):
    """:class:`Counters` of an rclpy node, published on ``/diagnostics`` every ``period`` s.

    Args:
        node: the node (its logger and clock are used; the timer runs in its executor).
        name: status name (default: the node's fully qualified name).
        period: seconds between reports (wall or sim time, the node's clock) [s].
        log_period: seconds between log lines of one drop reason [s].
        lock: held while the counters are read for a report, when other threads count.
    """

    def __init__(self, node, name: str | None = None, period: float = 1.0, log_period: float = 5.0, lock=None):
        from diagnostic_msgs.msg import DiagnosticArray

        super().__init__(log=node.get_logger().warning, log_period=log_period)
        self._lock = lock
        self.node = node
        self.name = name or node.get_fully_qualified_name()
        self.pub = node.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.timer = node.create_timer(period, self.publish)

    def publish(self, extra: Mapping[str, float] | None = None) -> None:
        """Publish the counters now."""
        from mrslam_ros.conversions import diagnostics_msg

        if self._lock is not None:
            with self._lock:
                counters, level, message = self.snapshot()
        else:
            counters, level, message = self.snapshot()
        counters.update(extra or {})
        self.pub.publish(diagnostics_msg(self.name, counters, self.node.get_clock().now().nanoseconds, level, message))


def incompatible_qos_events(diag: Counters, topic: str):
    """Subscription event callbacks that count, as ``incompatible_qos``, every publisher of
    ``topic`` whose QoS cannot match the subscription (a best-effort camera driver and a reliable
    subscription): nothing it publishes would arrive, and nothing else would say so."""
    from rclpy.event_handler import SubscriptionEventCallbacks

    def on_incompatible(status) -> None:
        diag.count("incompatible_qos", f"a publisher of {topic} offers QoS this subscription cannot match "
                   f"(policy {status.last_policy_kind})", max(int(status.total_count_change), 1))

    return SubscriptionEventCallbacks(incompatible_qos=on_incompatible)
