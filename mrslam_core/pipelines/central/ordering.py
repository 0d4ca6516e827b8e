"""Input ordering: the team's observation sets in stamp order, each paired with its odometry.

Observation sets wait in a queue and are released in stamp order once every *active* robot
(every robot of the config, unless silent for ``max_wait`` before the newest observation stamp,
or never heard from within ``max_wait`` of the team's first set) has delivered a set at least as
new, or once the set is ``max_wait`` older than the newest observation stamp (a late or silent
robot delays the team by at most ``max_wait``; odometry does not advance this clock, so
frontends that lag behind the odometry do not reorder anything). With ``team_step`` the sets of
one window of stamps are released together, once every active robot has delivered a set at or
after the window's end (or the end is ``max_wait`` old): one filter step. A released set is
paired with the robot's odometry interpolated at its stamp; the motion since the robot's previous
update is the filter's odometry input. Sightings of other robots that arrive apart from their
set (a topic of their own) join the set of their robot and stamp. Everything that cannot be used
is counted in the mapper's drops.
"""

from __future__ import annotations

import bisect
import heapq
from collections import Counter, deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from operator import itemgetter
from typing import Any

import numpy as np

from mrslam_core.geometry.se2 import wrap_angle
from mrslam_core.pipelines.central.config import CentralConfig
from mrslam_core.pipelines.central.state import set_from_state, sets_state
from mrslam_core.types import ObservationSet, RobotSighting


def _sightings_only(robot: str, stamp_ns: int, sightings: Sequence[RobotSighting]) -> ObservationSet:
    """A set of ``robot`` at ``stamp_ns`` holding sightings and no landmark measurement."""
    return ObservationSet(robot, int(stamp_ns), np.zeros((0, 3)), np.zeros((0, 3, 3)), sightings=tuple(sightings))


Odometry = Sequence[tuple[int, np.ndarray]]
"""A robot's buffered odometry: (stamp [ns], pose (3,) [m, rad]) in stamp order."""


def interpolate_odometry(buf: Odometry, stamp_ns: int) -> np.ndarray:
    """The pose (3,) of ``buf`` (not empty) at ``stamp_ns``: linear between the poses around it
    (θ along the shorter way, wrapped), the first or last pose outside their span. A binary
    search: the cost does not grow with the buffer."""
    i = bisect.bisect_left(buf, stamp_ns, key=itemgetter(0))
    if i == len(buf):
        return buf[-1][1].copy()
    if i == 0 or buf[i][0] == stamp_ns:
        out = buf[i][1].copy()
    else:
        (ta, a), (tb, b) = buf[i - 1], buf[i]
        f = (stamp_ns - ta) / (tb - ta)
        out = a + f * (b - a)
        out[2] = a[2] + f * wrap_angle(b[2] - a[2])
    out[2] = wrap_angle(out[2])
    return out


@dataclass(frozen=True)
class Pairing:
    """A released set's odometry (odom frame of its robot).

    Attributes:
        odom: (3,) the odometry pose at the set's stamp [m, rad].
        reference: (3,) the odometry pose the set's motion starts from: at the robot's previous
            update, or where its odometry started (at its start pose) before its first.
        previous_ns: stamp of the robot's previous update [ns]; None before its first.
        since_ns: stamp of the oldest buffered odometry pose [ns].
        buffer: the robot's buffered odometry when the set was paired (read before more
            odometry arrives).
    """

    odom: np.ndarray
    reference: np.ndarray
    previous_ns: int | None
    since_ns: int
    buffer: Odometry

    def at(self, stamp_ns: int) -> np.ndarray | None:
        """The odometry pose (3,) interpolated at ``stamp_ns``; None at or before the oldest
        buffered pose."""
        if stamp_ns <= self.since_ns:
            return None
        return interpolate_odometry(self.buffer, stamp_ns)


class Ordering:
    """The queue of observation sets, the odometry buffers and each robot's last update.

    Args:
        cfg: ``max_wait``, ``max_queue``, ``odom_buffer``, ``max_odom_gap`` and ``team_step`` apply.
        robots: robot names; their order breaks ties between sets of one stamp.
        drops: the mapper's drop counter (by reason), counted into.

    Attributes:
        now_ns: the newest observation stamp received [ns].
        last: robot -> (stamp [ns], odometry pose (3,)) of its last update.
    """

    def __init__(self, cfg: CentralConfig, robots: list[str], drops: Counter[str]):
        self.cfg = cfg
        self.robots = robots
        self.drops = drops
        self.now_ns = 0
        self.last: dict[str, tuple[int, np.ndarray]] = {}
        self._odom: dict[str, deque[tuple[int, np.ndarray]]] = {r: deque(maxlen=cfg.odom_buffer) for r in robots}
        #: heap of (stamp_ns, robot index, arrival number, set): stamp order, ties by robot
        self._queue: list[tuple[int, int, int, ObservationSet]] = []
        self._queued: set[tuple[str, int]] = set()
        #: (robot, stamp) -> sightings that came on their own, waiting for that set
        self._held: dict[tuple[str, int], list[RobotSighting]] = {}
        self._seq = 0
        self._latest_obs: dict[str, int] = {}
        self._first_ns: int | None = None
        self._wait_ns = int(cfg.max_wait * 1e9)
        if cfg.team_step < 0:
            raise ValueError("team_step must be >= 0")
        self._step_ns = int(round(cfg.team_step * 1e9))

    # ------------------------------------------------------------------ odometry
    def check_odometry(self, robot: str, stamp_ns: int, pose: np.ndarray) -> np.ndarray | None:
        """The odometry pose (3,) [m, rad] of ``robot`` at ``stamp_ns`` as floats if it can be
        buffered (:meth:`append_odometry`); None, counted, if not."""
        if robot not in self._odom:
            self.drops["unknown_robot"] += 1
            return None
        pose = np.asarray(pose, float)
        if pose.shape != (3,) or not np.isfinite(pose).all():
            self.drops["bad_odometry"] += 1
            return None
        buf = self._odom[robot]
        if buf and stamp_ns <= buf[-1][0]:
            self.drops["odometry_out_of_order" if stamp_ns < buf[-1][0] else "odometry_duplicate_stamp"] += 1
            return None
        return pose

    def latest_odometry(self, robot: str) -> tuple[int, np.ndarray] | None:
        """(stamp [ns], pose (3,)) of the robot's newest buffered odometry; None if none."""
        buf = self._odom[robot]
        return buf[-1] if buf else None

    def append_odometry(self, robot: str, stamp_ns: int, pose: np.ndarray) -> None:
        """Buffer a pose that :meth:`check_odometry` accepted."""
        self._odom[robot].append((int(stamp_ns), pose))

    def odometry_at(self, robot: str, stamp_ns: int) -> np.ndarray | None:
        """The robot's odometry pose (3,) at ``stamp_ns``: interpolated, or its newest for a later
        stamp; None without odometry."""
        buf = self._odom[robot]
        if not buf:
            return None
        if stamp_ns >= buf[-1][0]:
            return buf[-1][1]
        return interpolate_odometry(buf, stamp_ns)

    def path_length(self, robot: str, t0: int, t1: int) -> float:
        """Distance the odometry of ``robot`` covered between stamps ``t0`` and ``t1`` [m]."""
        xy = np.array([p[:2] for s, p in self._odom[robot] if t0 <= s <= t1]).reshape(-1, 2)
        return float(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum())

    def forget(self, robot: str) -> None:
        """Drop the robot's odometry and last update (its odometry restarted from a new origin)."""
        self._odom[robot].clear()
        self.last.pop(robot, None)

    # ------------------------------------------------------------------ observation sets
    def add_observations(self, obs: ObservationSet) -> bool:
        """Queue an observation set (base_link of ``obs.robot``); False, counted, if dropped.
        Sightings held or queued alone for its robot and stamp (:meth:`add_sightings`) join it."""
        if obs.robot not in self._odom:
            self.drops["unknown_robot"] += 1
            return False
        last = self.last.get(obs.robot)
        if last is not None and obs.stamp_ns <= last[0]:
            self.drops["stale_stamp"] += 1
            return False
        key = (obs.robot, int(obs.stamp_ns))
        if key in self._queued:
            i = self._queued_at(key)
            stamp, idx, seq, queued = self._queue[i]
            if len(queued) or not len(obs):
                self.drops["duplicate_stamp"] += 1
                return False
            # sightings queued alone before their set came (after a newer set of the robot): one set
            self._queue[i] = (stamp, idx, seq, replace(obs, sightings=obs.sightings + queued.sightings))
            return True
        held = self._held.pop(key, None)
        if held is not None:
            obs = replace(obs, sightings=obs.sightings + tuple(held))
        self._release_held(obs.robot, key[1])
        return self._queue_set(obs)

    def add_sightings(self, robot: str, stamp_ns: int, sightings: Sequence[RobotSighting]) -> bool:
        """Sightings by ``robot`` at ``stamp_ns`` that came apart from its observation set (the
        SLAM node's ``sightings`` topic): they join the set of that stamp, queued or still to come;
        if the robot's next set is newer they go as a set of their own. False, counted, if they
        are for a robot not in the team or a stamp already processed (``stale_sighting``)."""
        if robot not in self._odom or any(s.observer != robot for s in sightings):
            self.drops["unknown_robot"] += 1
            return False
        key = (robot, int(stamp_ns))
        last = self.last.get(robot)
        if last is not None and stamp_ns <= last[0]:
            self.drops["stale_sighting"] += len(sightings)
            return False
        if key in self._queued:
            i = self._queued_at(key)
            stamp, idx, seq, queued = self._queue[i]
            self._queue[i] = (stamp, idx, seq, replace(queued, sightings=queued.sightings + tuple(sightings)))
            return True
        if self._latest_obs.get(robot, -1) > stamp_ns:
            return self._queue_set(_sightings_only(robot, stamp_ns, sightings))
        self._held.setdefault(key, []).extend(sightings)
        return True

    def _queued_at(self, key: tuple[str, int]) -> int:
        """Position in the queue of the set of (robot, stamp) ``key`` (it is queued)."""
        return next(i for i, e in enumerate(self._queue) if (e[3].robot, e[0]) == key)

    def _release_held(self, robot: str | None = None, stamp_ns: float = np.inf) -> None:
        """Held sightings of ``robot`` (None: every robot) older than ``stamp_ns``, whose own set
        never came (a frame the frontend dropped after measuring them, or the end of the input),
        queued as sets of their own."""
        for key in sorted(k for k in self._held if robot in (None, k[0]) and k[1] < stamp_ns):
            self._queue_set(_sightings_only(key[0], key[1], self._held.pop(key)))

    def _queue_set(self, obs: ObservationSet) -> bool:
        key = (obs.robot, int(obs.stamp_ns))
        if len(self._queue) >= self.cfg.max_queue:
            _, _, _, old = heapq.heappop(self._queue)
            self._queued.discard((old.robot, old.stamp_ns))
            self.drops["queue_overflow"] += 1
        heapq.heappush(self._queue, (int(obs.stamp_ns), self.robots.index(obs.robot), self._seq, obs))
        self._queued.add(key)
        self._seq += 1
        self._latest_obs[obs.robot] = max(self._latest_obs.get(obs.robot, 0), int(obs.stamp_ns))
        self.now_ns = max(self.now_ns, int(obs.stamp_ns))
        if self._first_ns is None:
            self._first_ns = int(obs.stamp_ns)
        return True

    @property
    def queued(self) -> int:
        """Observation sets waiting."""
        return len(self._queue)

    def release(self, flush: bool, more: Callable[[], bool]) -> Iterator[list[ObservationSet]]:
        """The sets that are due (all of them with ``flush``), in stamp order, as team steps, each
        taken off the queue before it is yielded, while ``more()``; a due set whose robot has no
        odometry at its stamp is dropped (counted). A team step is one set, or with ``team_step``
        every set of one window of stamps, due once every active robot has delivered a set at or
        after the window's end (or the end is ``max_wait`` older than the newest set). With
        ``flush`` held sightings go as sets of their own first."""
        if flush:
            self._release_held()
        while self._queue and more():
            if self._step_ns:
                window = self._due_window(flush)
                if window is None:
                    return
                if window:
                    yield window
                continue
            stamp, _, _, obs = self._queue[0]
            overdue = flush or self.now_ns - stamp > self._wait_ns
            if not overdue and not self._others_caught_up(obs.robot, stamp):
                return
            buf = self._odom[obs.robot]
            if not buf or buf[-1][0] < stamp:
                if not overdue:
                    return  # its odometry is still on the way
                self._pop()
                self.drops["no_odometry_at_stamp"] += 1
                continue
            self._pop()
            yield [obs]

    def _due_window(self, flush: bool) -> list[ObservationSet] | None:
        """The sets of the oldest queued set's ``team_step`` window (n−1)·step < stamp ≤ n·step,
        taken off the queue, if they are due; None if they must wait."""
        end = -(-self._queue[0][0] // self._step_ns) * self._step_ns
        overdue = flush or self.now_ns - end > self._wait_ns
        if not overdue and not self._others_caught_up(None, end):
            return None
        window = sorted(e for e in self._queue if e[0] <= end)
        unpaired = [e for e in window if not self._odom[e[3].robot] or self._odom[e[3].robot][-1][0] < e[0]]
        if unpaired and not overdue:
            return None  # odometry still on the way
        self._queue = [e for e in self._queue if e[0] > end]
        heapq.heapify(self._queue)
        for stamp, _, _, obs in window:
            self._queued.discard((obs.robot, stamp))
        if unpaired:
            self.drops["no_odometry_at_stamp"] += len(unpaired)
        return [e[3] for e in window if not any(e is u for u in unpaired)]

    def _pop(self) -> None:
        stamp, _, _, obs = heapq.heappop(self._queue)
        self._queued.discard((obs.robot, stamp))

    def _others_caught_up(self, robot: str | None, stamp: int) -> bool:
        """True if every active robot but ``robot`` (None: every active robot) has delivered a set
        at ``stamp`` or later."""
        for other in self.robots:
            # a robot not heard from yet is waited for from the team's first set on
            latest = self._latest_obs.get(other, self._first_ns - 1)
            if other == robot or self.now_ns - latest > self._wait_ns:
                continue  # a robot silent for longer than max_wait is not waited for
            if latest < stamp:
                return False
        return True

    def pair(self, obs: ObservationSet) -> Pairing | None:
        """The odometry of a released set; None, counted, if its stamp is older than the robot's
        buffered odometry or falls in a hole longer than ``max_odom_gap``."""
        buf = self._odom[obs.robot]
        if obs.stamp_ns < buf[0][0]:
            self.drops["no_odometry_at_stamp"] += 1
            return None
        i = bisect.bisect_left(buf, obs.stamp_ns, key=itemgetter(0))
        if (0 < i < len(buf) and buf[i][0] != obs.stamp_ns
                and (buf[i][0] - buf[i - 1][0]) * 1e-9 > self.cfg.max_odom_gap):
            self.drops["odometry_gap"] += 1
            return None
        odom = interpolate_odometry(buf, obs.stamp_ns)
        prev = self.last.get(obs.robot)
        reference = buf[0][1] if prev is None else prev[1]
        return Pairing(odom, reference, None if prev is None else prev[0], buf[0][0], buf)

    # ------------------------------------------------------------------ checkpoint
    def state(self) -> dict[str, Any]:
        """Everything above as JSON values and arrays: ``odom_t_{k}`` int64 (N,) [ns] and
        ``odom_p_{k}`` (N, 3) per robot index k, ``queue`` ([robot, stamp_ns, arrival]) in release
        order with the sets' arrays (``queue_*_{i}``), ``held`` ([robot, stamp_ns]) with the held
        sightings (``held_sight_*_{i}``), ``last`` (robot: [stamp_ns, x, y, θ])."""
        queue = sorted(self._queue, key=lambda e: e[:3])
        out: dict[str, Any] = {
            "last": {r: [s, *map(float, p)] for r, (s, p) in self.last.items()},
            "latest_obs": dict(self._latest_obs), "first_ns": self._first_ns, "now_ns": self.now_ns,
            "seq": self._seq, "queue": [[o.robot, stamp, seq] for stamp, _, seq, o in queue],
            **sets_state("queue", [o for *_, o in queue]),
            "held": [[r, t] for r, t in sorted(self._held)],
            **sets_state("held", [_sightings_only(r, t, self._held[(r, t)]) for r, t in sorted(self._held)]),
        }
        for k, r in enumerate(self.robots):
            out[f"odom_t_{k}"] = np.array([t for t, _ in self._odom[r]], np.int64)
            out[f"odom_p_{k}"] = np.array([p for _, p in self._odom[r]], float).reshape(-1, 3)
        return out

    def load_state(self, state: dict[str, Any]) -> None:
        """Take the state :meth:`state` gave (into a new part, of the same robots)."""
        self.last = {r: (int(v[0]), np.array(v[1:], float)) for r, v in state["last"].items()}
        self._latest_obs = {r: int(v) for r, v in state["latest_obs"].items()}
        self._first_ns = state["first_ns"]
        self.now_ns, self._seq = int(state["now_ns"]), int(state["seq"])
        for k, r in enumerate(self.robots):
            self._odom[r].extend(zip(state[f"odom_t_{k}"].tolist(), state[f"odom_p_{k}"]))
        for i, (robot, stamp, seq) in enumerate(state["queue"]):
            obs = set_from_state(state, "queue", i, robot, stamp)
            self._queue.append((int(stamp), self.robots.index(robot), int(seq), obs))
            self._queued.add((robot, int(stamp)))
        heapq.heapify(self._queue)
        for i, (robot, stamp) in enumerate(state.get("held", [])):  # a checkpoint before held sightings has none
            self._held[(robot, int(stamp))] = list(set_from_state(state, "held", i, robot, stamp).sightings)
