"""``mrslam replay BAG``: play a rosbag2 recording (sqlite3 or mcap) into the running nodes.

Every message is published as the serialized bytes stored in the bag (rclpy publishers accept
``bytes``), at its original log time scaled by ``--rate``, with ``/clock`` carrying the bag's time
(so nodes run with ``use_sim_time: true``). Publishers use the QoS recorded in the bag (latched
``/tf_static`` stays transient-local). With ``--loop`` the bag starts over when it ends: the clock
then jumps backwards, which the nodes must count and survive.

``--view`` also starts the view node (a Foxglove WebSocket server, :mod:`mrslam_ros.view_node`) for
the bag's robots, stopped with the replay.

``--offline`` feeds the bag straight into the core without ROS; that mode lives in
:data:`OFFLINE_MODULE` (its ``main(argv) -> int`` receives the same arguments).
"""

from __future__ import annotations

import argparse
import importlib
import sys
import time
from collections import Counter
from collections.abc import Callable, Iterable
from pathlib import Path

from mrslam_ros.bag import BagError, bag_info, message_class, read_bag
from mrslam_ros.launch import add_view_arguments, view_spec

#: The module of the offline replay (bag -> core, no ROS), owned by the SLAM pipeline.
OFFLINE_MODULE = "mrslam_ros.replay_offline"


class BagPlayer:
    """Publish a bag's messages with their original timing, and ``/clock``.

    Args:
        node: the rclpy node to publish from (it needs no spinning).
        path: the bag folder.
        rate: playback speed factor (2 = twice as fast), > 0.
        loop: start over at the end (until :meth:`stop` or ``max_loops``).
        topics: only these topics (default: all in the bag).
        clock: publish ``/clock`` (the bag's ``/clock`` topic, if any, is then not replayed).
        clock_hz: ``/clock`` messages per second of wall time between bag messages.
        wait_for_subscribers: seconds to wait, before the first message, until every topic of
            the bag has at least one matched subscription (0: start at once); see ``settle``.
            A publisher that has matched a subscription can still be unknown to that subscription
            for a moment (DDS discovery is two-sided), and what it publishes then is lost: so the
            first message of every topic then goes out ahead of the bag's time and the player waits,
            within the same bound, until every matched reliable subscription acknowledged it
            (:meth:`publish_first`).
        settle: once some topics have a matched subscription, stop waiting when no other topic
            gained one for this long [s]: the rest have no subscriber in the graph (a dataset bag's
            ground truth and /tf_static), and a new participant is discovered with every endpoint
            of the graph at once.
        start_delay: seconds to wait after that, publishing ``/clock`` at the bag's start.

    Raises:
        BagError: not a bag, a bad rate, or a topic whose message type is not importable.
    """

    def __init__(self, node, path: str | Path, rate: float = 1.0, loop: bool = False,
                 topics: Iterable[str] | None = None, clock: bool = True, clock_hz: float = 50.0,
                 wait_for_subscribers: float = 0.0, start_delay: float = 0.0, settle: float = 1.0):
        from rosgraph_msgs.msg import Clock

        from mrslam_ros.qos import CLOCK, from_bag_qos

        if not rate > 0:
            raise BagError(f"rate must be > 0, got {rate}")
        self.node, self.path, self.rate, self.loop = node, Path(path), float(rate), loop
        self.info = bag_info(path)
        wanted = set(topics) if topics is not None else set(self.info.topics)
        unknown = wanted - set(self.info.topics)
        if unknown:
            raise BagError(f"topics {sorted(unknown)} are not in {path} (it has {sorted(self.info.topics)})")
        if clock:
            wanted.discard("/clock")
        self.topics = sorted(wanted)
        self.clock_hz = float(clock_hz)
        self.wait_for_subscribers = float(wait_for_subscribers)
        self.start_delay = float(start_delay)
        self.settle = float(settle)
        self.published: Counter[str] = Counter()
        self.loops = 0
        self._stop = False
        self._pubs = {t: node.create_publisher(message_class(self.info.topics[t].msgtype), t,
                                               from_bag_qos(self.info.topics[t].offered_qos, t))
                      for t in self.topics}
        self._clock_cls = Clock
        self._clock_pub = node.create_publisher(Clock, "/clock", CLOCK) if clock else None

    def stop(self) -> None:
        """Make :meth:`run` return after the message being published (thread-safe)."""
        self._stop = True

    def publish_clock(self, stamp_ns: int) -> None:
        if self._clock_pub is None:
            return
        from mrslam_ros.conversions import ns_to_stamp

        self._clock_pub.publish(self._clock_cls(clock=ns_to_stamp(stamp_ns)))

    def publish_first(self, prime: bool) -> set[str]:
        """Publish the first message of topics ahead of the bag's time; returns those topics (their
        first message is not published again in its turn, and is counted in ``published``).

        Args:
            prime: every topic, then wait until each matched reliable subscription acknowledged
                its first message (at most ``wait_for_subscribers`` s in all): a subscription acks
                only once it knows the publisher, so this ends the two-sided discovery that a
                matched count on the publisher's side does not. In one CI run a central node
                lost a robot's first 1.6 s of sets, played after the matched count and a 1 s
                start delay. Without ``prime`` only the ``sensor_msgs/msg/CameraInfo`` topics.
                Either way the calibration goes first: a camera's calibration is static, and a
                frontend drops every image pair until it has both cameras' CameraInfo. Played
                only in their turn, they went out in one burst with the first two 450 kB images
                of a dataset bag, and in 9 of 23 live runs on a loaded 2-core machine some were
                lost and repaired only by the reliable writer's next heartbeat, 3 s later: 7-16 of
                KITTI's first frames were dropped (``no_camera_info``); primed together with the
                first images, a first pair reached a frontend before its right CameraInfo once.
        """
        from rclpy.duration import Duration

        calibration = {t for t in self.topics if self.info.topics[t].msgtype == "sensor_msgs/msg/CameraInfo"}
        wanted = set(self.topics) if prime else calibration
        first: dict[str, bytes] = {}
        if wanted:
            for m in read_bag(self.path, sorted(wanted)):
                first.setdefault(m.topic, m.data)
                if len(first) == len(wanted):
                    break
        end = time.monotonic() + self.wait_for_subscribers
        for group in (calibration, wanted - calibration):  # the calibration acknowledged first
            topics = sorted(group & first.keys())
            for topic in topics:
                self._pubs[topic].publish(first[topic])
                self.published[topic] += 1
            for topic in topics if prime else ():
                left = end - time.monotonic()
                if left <= 0 or self._stop:
                    break
                self._pubs[topic].wait_for_all_acked(Duration(nanoseconds=int(left * 1e9)))
        return set(first)

    def _wait_for_subscribers(self) -> None:
        """Until every topic has a matched subscription, or ``settle`` s after the last topic that
        gained one, at most ``wait_for_subscribers`` s. Waiting for every topic alone, a bag with
        topics nobody subscribes to always waited the whole time, and the player's participant
        was discovered 1-3.4 s after its start on a loaded 2-core machine: the first frames of a
        dataset bag were lost with the default 2 s wait, and with them the robot's start."""
        now = time.monotonic()
        end, last_new, matched = now + self.wait_for_subscribers, now, 0
        while now < end and not self._stop:
            n = sum(p.get_subscription_count() > 0 for p in self._pubs.values())
            if n == len(self._pubs) or (matched and n <= matched and now - last_new >= self.settle):
                return
            if n > matched:
                matched, last_new = n, now
            time.sleep(0.02)
            now = time.monotonic()

    def _sleep_until(self, wall: float, bag_ns_at: Callable[[float], int]) -> None:
        """Sleep until monotonic time ``wall``, publishing /clock at ``clock_hz`` meanwhile."""
        period = 1.0 / self.clock_hz if self.clock_hz > 0 else float("inf")
        while not self._stop:
            now = time.monotonic()
            if now >= wall:
                return
            time.sleep(min(period, wall - now))
            if time.monotonic() < wall:
                self.publish_clock(bag_ns_at(time.monotonic()))

    def run(self, max_loops: int | None = None, progress: Callable[[int, int], None] | None = None) -> int:
        """Play the bag (blocking); returns the number of messages published.

        Args:
            max_loops: with ``loop``, stop after this many passes (None: until :meth:`stop`).
            progress: called with (messages published, messages per pass) after each message.
        """
        if self.wait_for_subscribers > 0:
            self._wait_for_subscribers()
        ahead = self.publish_first(prime=self.wait_for_subscribers > 0)
        if self.start_delay > 0:
            self.publish_clock(self.info.start_ns)
            self._sleep_until(time.monotonic() + self.start_delay, lambda _: self.info.start_ns)
        per_pass = sum(self.info.topics[t].count for t in self.topics)
        total = 0
        while not self._stop:
            t0_bag = self.info.start_ns
            t0_wall = time.monotonic()

            def bag_ns_at(wall: float, t0_bag: int = t0_bag, t0_wall: float = t0_wall) -> int:
                return t0_bag + int((wall - t0_wall) * self.rate * 1e9)

            self.publish_clock(t0_bag)
            for m in read_bag(self.path, self.topics):
                if m.topic in ahead:  # its first message went out ahead of time (first pass only)
                    ahead.discard(m.topic)
                    total += 1
                    continue
                self._sleep_until(t0_wall + (m.stamp_ns - t0_bag) * 1e-9 / self.rate, bag_ns_at)
                if self._stop:
                    break
                self.publish_clock(m.stamp_ns)
                self._pubs[m.topic].publish(m.data)
                self.published[m.topic] += 1
                total += 1
                if progress is not None:
                    progress(total, per_pass)
            self.loops += 1
            if not self.loop or (max_loops is not None and self.loops >= max_loops):
                break
        self.flush()
        return total

    def flush(self, timeout: float = 2.0) -> bool:
        """Wait until reliable subscribers acknowledged everything published (at most ``timeout``
        s per publisher), so a player that exits next does not lose its last messages."""
        from rclpy.duration import Duration

        pubs = list(self._pubs.values()) + ([self._clock_pub] if self._clock_pub is not None else [])
        acked = True
        for p in pubs:  # every publisher, even after one timed out
            acked = p.wait_for_all_acked(Duration(seconds=timeout)) and acked
        return acked


def parse_args(argv: list[str]) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="mrslam replay", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("bag", help="rosbag2 folder (sqlite3 or mcap)")
    ap.add_argument("--rate", type=float, default=1.0, help="playback speed factor (default 1)")
    ap.add_argument("--loop", action="store_true", help="start over at the end (the clock jumps back)")
    ap.add_argument("--topics", nargs="+", help="only these topics")
    ap.add_argument("--no-clock", action="store_true", help="do not publish /clock")
    ap.add_argument("--clock-hz", type=float, default=50.0, help="/clock rate between messages (wall Hz)")
    ap.add_argument("--wait", type=float, default=10.0,
                    help="seconds to wait for subscribers of every topic before playing, or 1 s after the "
                         "last topic that got one (default 10)")
    ap.add_argument("--delay", type=float, default=0.5,
                    help="seconds to wait after that before the first message (default 0.5)")
    add_view_arguments(ap)
    ap.add_argument("--offline", action="store_true", help="feed the bag straight into the core (no ROS)")
    ap.add_argument("--out", help="run folder (with --offline; default <bag>_offline)")
    ap.add_argument("--config", help="central node parameters (with --offline; default slam.yaml beside the bag)")
    ap.add_argument("--quiet", action="store_true", help="no progress bar (with --offline)")
    ap.add_argument("--seed", type=int, help="the filter's seed instead of the config's (with --offline)")
    ap.add_argument("--downtime", metavar="A:B", help="with --offline: the central node killed after its "
                    "checkpoint at A s and back with --resume at B s (stamp time)")
    return ap.parse_args(argv)


def main(argv: list[str]) -> int:
    args = parse_args(argv)
    if args.offline:
        try:
            offline = importlib.import_module(OFFLINE_MODULE)
        except ModuleNotFoundError as exc:
            if exc.name != OFFLINE_MODULE:
                raise
            print(f"mrslam replay: --offline needs {OFFLINE_MODULE}, which is not written yet", file=sys.stderr)
            return 2
        return int(offline.main(argv) or 0)

    import rclpy

    try:
        info = bag_info(args.bag)
    except BagError as exc:
        print(f"mrslam replay: {exc}", file=sys.stderr)
        return 2
    viewer = None
    if args.view:
        from mrslam_ros.launch import Launcher, LaunchConfig

        # the view node finds the bag's robots in the graph as the player publishes them
        viewer = Launcher(LaunchConfig(nodes=[view_spec(args)], use_sim_time=not args.no_clock), log=sys.stderr)
        viewer.start()
    rclpy.init()
    node = rclpy.create_node("mrslam_replay")
    try:
        player = BagPlayer(node, args.bag, rate=args.rate, loop=args.loop, topics=args.topics,
                           clock=not args.no_clock, clock_hz=args.clock_hz, wait_for_subscribers=args.wait,
                           start_delay=args.delay)
        print(f"mrslam replay: {info.count} messages on {len(info.topics)} topics, {info.duration_s:.1f} s "
              f"({info.storage}), rate {args.rate:g}{', looping' if args.loop else ''}", flush=True)
        n = player.run()
        print(f"mrslam replay: published {n} messages", flush=True)
        return 0
    except BagError as exc:
        print(f"mrslam replay: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 0
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        if viewer is not None:
            viewer.stop()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
