"""Approximate-time synchronisation of several message streams (message_filters is not on PyPI).

:class:`ApproximateTimeSync` works on integer nanosecond stamps and any payload, so it is tested
without ROS. :class:`StereoSync` is the frontend's use of it: left/right ``Image`` and
``CameraInfo`` (four streams) grouped into one :class:`StereoFrame`.

Policy: every stream keeps a bounded queue, ordered by stamp. After each arrival the sets made of
one queued message per stream, all within ``slop_ns`` of each other, are candidates; the one with the
oldest newest-stamp (then the smallest spread) is emitted at once (like message_filters' Python
ApproximateTimeSynchronizer, it does not wait for a possibly better match). Emitted messages leave
their queues together with every older message, which can no longer be emitted. Nothing is ever
raised for bad timing; every message that does not end up in a set is counted in ``drops`` by reason:

- ``overflow``: pushed out of a full queue (its partners never came in time);
- ``unmatched``: older than a message of the same stream that was emitted;
- ``late``: arrived with a stamp at or before the last emitted stamp of its stream (out of order);
- ``duplicate``: same stamp as a message already queued on its stream.
"""

from __future__ import annotations

import bisect
from collections import Counter
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple


class ApproximateTimeSync:
    """Group messages of ``n`` streams whose stamps lie within ``slop_ns`` of each other.

    Args:
        n: number of streams (>= 1).
        slop_ns: largest spread of the stamps in one set [ns] (>= 0; 0 = exact time).
        queue_size: messages kept per stream while waiting for partners (>= 1).

    Raises:
        ValueError: a bad argument.
    """

    def __init__(self, n: int, slop_ns: int, queue_size: int = 5):
        if n < 1 or slop_ns < 0 or queue_size < 1:
            raise ValueError(f"need n >= 1, slop_ns >= 0, queue_size >= 1 (got {n}, {slop_ns}, {queue_size})")
        self.n, self.slop_ns, self.queue_size = n, int(slop_ns), int(queue_size)
        self._stamps: list[list[int]] = [[] for _ in range(n)]
        self._msgs: list[list[Any]] = [[] for _ in range(n)]
        self._last: list[int | None] = [None] * n
        self.drops: Counter[str] = Counter()
        self.emitted = 0

    def queued(self) -> list[int]:
        """Messages waiting per stream."""
        return [len(s) for s in self._stamps]

    def add(self, stream: int, stamp_ns: int, msg: Any) -> list[Any] | None:
        """Offer one message; returns the n messages of a completed set (stream order) or None.

        Raises:
            IndexError: ``stream`` is not in [0, n).
        """
        if not 0 <= stream < self.n:
            raise IndexError(f"stream {stream} not in [0, {self.n})")
        stamp_ns = int(stamp_ns)
        last = self._last[stream]
        if last is not None and stamp_ns <= last:
            self.drops["late"] += 1
            return None
        stamps, msgs = self._stamps[stream], self._msgs[stream]
        k = bisect.bisect_left(stamps, stamp_ns)
        if k < len(stamps) and stamps[k] == stamp_ns:
            self.drops["duplicate"] += 1
            return None
        stamps.insert(k, stamp_ns)
        msgs.insert(k, msg)
        if len(stamps) > self.queue_size:
            del stamps[0], msgs[0]
            self.drops["overflow"] += 1
        return self._match()

    def _nearest(self, stream: int, t: int) -> int | None:
        stamps = self._stamps[stream]
        if not stamps:
            return None
        k = bisect.bisect_left(stamps, t)
        best = min((j for j in (k - 1, k) if 0 <= j < len(stamps)), key=lambda j: abs(stamps[j] - t))
        return best

    def _match(self) -> list[Any] | None:
        if not all(self._stamps):
            return None
        best: tuple[tuple[int, int], list[int]] | None = None
        for pivot in range(self.n):
            for t in self._stamps[pivot]:
                pick = [self._nearest(s, t) for s in range(self.n)]
                chosen = [self._stamps[s][j] for s, j in enumerate(pick)]  # type: ignore[index]
                key = (max(chosen), max(chosen) - min(chosen))  # oldest set first, then the tightest
                if key[1] <= self.slop_ns and (best is None or key < best[0]):
                    best = (key, pick)  # type: ignore[assignment]
        if best is None:
            return None
        out = []
        for s, j in enumerate(best[1]):
            out.append(self._msgs[s][j])
            self._last[s] = self._stamps[s][j]
            self.drops["unmatched"] += j
            del self._stamps[s][: j + 1], self._msgs[s][: j + 1]
        self.emitted += 1
        return out


class StereoFrame(NamedTuple):
    """A synchronised stereo frame (ROS messages) and its stamp (the left image's) [ns]."""

    stamp_ns: int
    left: Any
    right: Any
    left_info: Any
    right_info: Any


def _stamp_ns(msg: Any) -> int:
    s = msg.header.stamp
    return int(s.sec) * 1_000_000_000 + int(s.nanosec)


class StereoSync:
    """Left/right ``sensor_msgs/Image`` + ``CameraInfo`` -> :class:`StereoFrame` via ``callback``.

    Feed the four subscriptions into :meth:`left_image`, :meth:`right_image`, :meth:`left_info`,
    :meth:`right_info`. Drops are counted in ``drops`` (see the module's policy).

    Args:
        callback: called with each completed StereoFrame.
        slop_ns: largest spread of the four stamps [ns] (a hardware-triggered pair has 0).
        queue_size: messages kept per stream.
    """

    LEFT, LEFT_INFO, RIGHT, RIGHT_INFO = range(4)

    def __init__(self, callback: Callable[[StereoFrame], None], slop_ns: int = 5_000_000, queue_size: int = 5):
        self.callback = callback
        self.sync = ApproximateTimeSync(4, slop_ns, queue_size)

    @property
    def drops(self) -> Counter[str]:
        return self.sync.drops

    def _add(self, stream: int, msg: Any) -> None:
        out: Sequence[Any] | None = self.sync.add(stream, _stamp_ns(msg), msg)
        if out is not None:
            left, left_info, right, right_info = out
            self.callback(StereoFrame(_stamp_ns(left), left, right, left_info, right_info))

    def left_image(self, msg: Any) -> None:
        self._add(self.LEFT, msg)

    def right_image(self, msg: Any) -> None:
        self._add(self.RIGHT, msg)

    def left_info(self, msg: Any) -> None:
        self._add(self.LEFT_INFO, msg)

    def right_info(self, msg: Any) -> None:
        self._add(self.RIGHT_INFO, msg)
