"""The central mapper: the parts composed into one update per team step, and checkpoints.

An update takes the sets the :class:`~.ordering.Ordering` released as one team step (one set, or
with ``team_step`` the sets of one window) with their odometry, gives each to the filter that
maps its robot (:class:`~.lifecycle.Lifecycle`: the central one, or the robot's local one before
its merge) with its sightings of other robots, with the :class:`~.corrections.Corrections` before
and after the filter step, and records each robot's pose. A checkpoint is the central filter plus
each part's state.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mrslam_core.pipelines.central.config import CentralConfig
from mrslam_core.pipelines.central.corrections import Corrections
from mrslam_core.pipelines.central.lifecycle import Lifecycle
from mrslam_core.pipelines.central.ordering import Ordering
from mrslam_core.slam.filter import FilterInputError, MultiRobotFastSLAM, RobotUpdate
from mrslam_core.types import ObservationSet, RobotSighting

#: the parts of a checkpoint's mapper state, each under its name (``mapper``: the mapper's own)
PARTS = ("mapper", "ordering", "lifecycle", "corrections")


@dataclass(frozen=True)
class Processed:
    """One filter update the mapper made.

    Attributes:
        robot: whose update.
        stamp_ns: its stamp [ns].
        pose: (3,) the robot's weighted-mean pose after the update, map frame.
        cov: (3, 3) its covariance.
        odom: (3,) the robot's odometry pose at the stamp, odom frame.
        step_ms: wall time of the filter step [ms].
        merged: the pose is in the map frame (False: an unknown-start robot not merged yet,
            whose pose is in its own start frame, or a robot back from silence awaiting its
            re-localisation, at its dead-reckoned pose).
    """

    robot: str
    stamp_ns: int
    pose: np.ndarray
    cov: np.ndarray
    odom: np.ndarray
    step_ms: float
    merged: bool = True


class CentralMapper:
    """Queue, order and pair the team's messages; run the filter; keep the trajectories.

    Args:
        cfg: robots, start poses, buffer sizes and the filter.

    Attributes:
        slam: the central filter (map frame).
        ordering, lifecycle, corrections: the parts.
        drops: everything that could not be used, by reason (every part counts here).
        update_ms: wall time of each update [ms].
        trajectory: robot -> [(stamp_ns, pose (3,) map frame)] of its central-filter updates.
        held: robot -> stamps of the updates made while it awaited its re-localisation (not
            reported).
    """

    def __init__(self, cfg: CentralConfig):
        self.cfg = cfg
        self.robots = list(cfg.robots)
        self.drops: Counter[str] = Counter()
        self.lifecycle = Lifecycle(cfg, self.drops)
        self.slam = self.lifecycle.central_filter()
        self.ordering = Ordering(cfg, self.robots, self.drops)
        self.corrections = Corrections(cfg, self.robots, self.drops)
        self.update_ms: list[float] = []
        self.trajectory: dict[str, list[tuple[int, np.ndarray]]] = {r: [] for r in self.robots}
        self.held: dict[str, set[int]] = {r: set() for r in self.robots}

    # ------------------------------------------------------------------ the parts' results
    @property
    def local(self) -> dict[str, MultiRobotFastSLAM]:
        """Unknown-start (or restarted) robots not merged yet: their local filters."""
        return self.lifecycle.local

    @property
    def merges(self) -> list[dict]:
        """Every alignment attempt of a local map (:attr:`Lifecycle.merges`)."""
        return self.lifecycle.merges

    @property
    def restarts(self) -> list[dict]:
        """Every odometry reset (:attr:`Lifecycle.restarts`)."""
        return self.lifecycle.restarts

    @property
    def relocalizations(self) -> list[dict]:
        """Every re-localisation after a gap and move by a map check (:attr:`Corrections.relocalizations`)."""
        return self.corrections.relocalizations

    @property
    def map_checks(self) -> Counter[str]:
        """Map checks made, by outcome."""
        return self.corrections.map_checks

    @property
    def now_ns(self) -> int:
        """The newest observation stamp received [ns]."""
        return self.ordering.now_ns

    @property
    def queued(self) -> int:
        """Observation sets waiting."""
        return self.ordering.queued

    # ------------------------------------------------------------------ input
    def add_odometry(self, robot: str, stamp_ns: int, pose: np.ndarray) -> bool:
        """Buffer the odometry pose (3,) [m, rad] of ``robot`` at ``stamp_ns``; False if dropped.
        A pose that jumped further than a robot drives restarts the robot (:class:`Lifecycle`)."""
        pose = self.ordering.check_odometry(robot, stamp_ns, pose)
        if pose is None:
            return False
        latest = self.ordering.latest_odometry(robot)
        if latest is not None and self.lifecycle.restart_if_reset(robot, *latest, int(stamp_ns), pose):
            self.ordering.forget(robot)
            self.corrections.forget(robot)
        self.ordering.append_odometry(robot, stamp_ns, pose)
        return True

    def add_observations(self, obs: ObservationSet) -> bool:
        """Queue an observation set (base_link of ``obs.robot``), with its sightings of other
        robots (scored in the weights of the filter that maps both); False if dropped."""
        return self.ordering.add_observations(obs)

    def add_sightings(self, robot: str, stamp_ns: int, sightings: Sequence[RobotSighting]) -> bool:
        """Sightings of other robots by ``robot`` at ``stamp_ns`` [ns] that come apart from its
        observation set (a topic of their own): they join that set
        (:meth:`Ordering.add_sightings`); False, counted, if dropped."""
        return self.ordering.add_sightings(robot, stamp_ns, sightings)

    # ------------------------------------------------------------------ processing
    def process(self, flush: bool = False, budget_s: float | None = None, max_sets: int | None = None) -> list[Processed]:
        """Run the filter on every set that is due (all of them with ``flush``), in stamp order,
        or only for about ``budget_s`` wall seconds or ``max_sets`` sets (the rest stays queued;
        with ``team_step``, whole windows)."""
        done: list[Processed] = []
        until = None if budget_s is None else time.perf_counter() + budget_s

        def more() -> bool:
            return (until is None or time.perf_counter() < until) and (max_sets is None or len(done) < max_sets)

        for sets in self.ordering.release(flush, more):
            done += self._update(sets)
        return done

    def _update(self, sets: list[ObservationSet]) -> list[Processed]:
        """One team step: ``sets`` (in stamp order) paired, corrected and given to the filters
        that map their robots in one step each (one resampling decision); the robots' poses
        after it, at each robot's last set."""
        t0 = time.perf_counter()
        steps: dict[int, tuple[MultiRobotFastSLAM, list[RobotUpdate]]] = {}
        made: list[tuple[ObservationSet, MultiRobotFastSLAM, np.ndarray, bool]] = []
        before = dict(self.ordering.last)
        for obs in sets:
            pairing = self.ordering.pair(obs)
            if pairing is None:
                continue
            filt = self.lifecycle.local.get(obs.robot, self.slam)
            motion = self.corrections.before_step(self.slam, filt, obs, pairing, self.ordering.path_length)
            held = self.corrections.hold(obs)
            sightings = () if held else self._sightings(filt, obs)
            steps.setdefault(id(filt), (filt, []))[1].append(
                RobotUpdate(obs.robot, obs.stamp_ns, motion, None if held else obs, sightings))
            self.ordering.last[obs.robot] = (obs.stamp_ns, pairing.odom)
            made.append((obs, filt, pairing.odom, held))
        failed: set[int] = set()
        if id(self.slam) in steps:
            self.lifecycle.hold_gauge(self.slam)
        for key, (filt, updates) in steps.items():
            try:
                filt.step(updates)
            except FilterInputError:
                failed.add(key)
        ms = (time.perf_counter() - t0) * 1e3
        self.update_ms.append(ms)
        last = {}  # robot -> stamp of its last set of this step
        for obs, filt, odom, held in made:
            if id(filt) in failed:
                self.drops["bad_observations"] += 1
                if obs.robot in before:  # the motion stays to be applied with its next set
                    self.ordering.last[obs.robot] = before[obs.robot]
                else:
                    self.ordering.last.pop(obs.robot, None)
                continue
            if filt is self.slam and not held:
                self.corrections.after_step(self.slam, obs, odom)
            elif filt is not self.slam:
                self.lifecycle.updated(self.slam, obs.robot, obs.stamp_ns)
            last[obs.robot] = obs.stamp_ns
        self.lifecycle.rendezvous(self.slam, [obs for obs, filt, _, _ in made if id(filt) not in failed])
        done = []
        for obs, _, odom, held in made:
            if last.get(obs.robot) != obs.stamp_ns:
                continue  # its step failed, or the robot has a later set in this step (its pose is there)
            filt = self.lifecycle.local.get(obs.robot, self.slam)
            est = filt.estimate()
            k = filt.index[obs.robot]
            if filt is self.slam:
                self.trajectory[obs.robot].append((obs.stamp_ns, est.mean[k].copy()))
                if held:
                    self.held[obs.robot].add(obs.stamp_ns)
            # a robot back from silence and not placed again has no map pose yet, as an unknown-start
            # robot before its merge: its dead-reckoned pose is neither published nor reported
            merged = filt is self.slam and not held
            done.append(Processed(obs.robot, obs.stamp_ns, est.mean[k].copy(), est.cov[k].copy(), odom, ms, merged))
        return done

    def _sightings(self, filt: MultiRobotFastSLAM, obs: ObservationSet) -> tuple[RobotSighting, ...]:
        """The sightings of ``obs`` that ``filt`` can score: of robots it holds (a robot not merged
        yet, or measured by one, is in no common frame with the other; counted as
        ``unmapped_sighting``)."""
        kept = tuple(s for s in obs.sightings if s.target in filt.index)
        if len(kept) < len(obs.sightings):
            self.drops["unmapped_sighting"] += len(obs.sightings) - len(kept)
        return kept

    # ------------------------------------------------------------------ results
    def trajectories(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """robot -> (stamps (N,) [ns], poses (N, 3) map frame) of every update made in the map
        (not those awaiting a re-localisation)."""
        out = {}
        for r, rows in self.trajectory.items():
            rows = [row for row in rows if row[0] not in self.held[r]]
            stamps = np.array([s for s, _ in rows], np.int64)
            poses = np.array([p for _, p in rows]).reshape(-1, 3)
            out[r] = (stamps, poses)
        return out

    def counters(self) -> dict[str, int]:
        """Drops of the mapper and of the filter, by reason."""
        out = Counter(self.drops)
        out.update({f"filter_{k}": v for k, v in self.slam.dropped.items()})
        for local in self.local.values():
            out.update({f"filter_{k}": v for k, v in local.dropped.items()})
        return dict(out)

    # ------------------------------------------------------------------ checkpoints
    def state(self) -> dict[str, dict[str, Any]]:
        """Each part's state by name (:data:`PARTS`; JSON values and numeric arrays), ``mapper``
        the mapper's own: ``drops``, ``update_ms`` (N,) [ms], and per robot index k
        ``traj_t_{k}`` int64 (N,) [ns], ``traj_p_{k}`` (N, 3) map frame, ``held_t_{k}`` int64 [ns]."""
        own: dict[str, Any] = {"drops": dict(self.drops), "update_ms": np.asarray(self.update_ms, float)}
        for k, r in enumerate(self.robots):
            own[f"traj_t_{k}"] = np.array([t for t, _ in self.trajectory[r]], np.int64)
            own[f"traj_p_{k}"] = np.array([p for _, p in self.trajectory[r]], float).reshape(-1, 3)
            own[f"held_t_{k}"] = np.array(sorted(self.held[r]), np.int64)
        return {"mapper": own, "ordering": self.ordering.state(), "lifecycle": self.lifecycle.state(),
                "corrections": self.corrections.state()}

    def _load_state(self, states: dict[str, dict[str, Any]]) -> None:
        """Take the states :meth:`state` gave (into a new mapper, beside its restored filter)."""
        own = states["mapper"]
        self.drops.update(own["drops"])
        self.update_ms = [float(x) for x in own["update_ms"]]
        for k, r in enumerate(self.robots):
            self.trajectory[r] = list(zip(own[f"traj_t_{k}"].tolist(), own[f"traj_p_{k}"]))
            self.held[r] = set(own[f"held_t_{k}"].tolist()) if f"held_t_{k}" in own else set()
        self.ordering.load_state(states["ordering"])
        self.lifecycle.load_state(states["lifecycle"])
        self.corrections.load_state(states["corrections"])

    def save(self, path: str | Path) -> Path:
        """Write the central filter and every part's state atomically to ``path`` (see
        :mod:`mrslam_core.slam.checkpoint`; the parts' values as ``extra`` entries
        ``<part>.<key>``, with the robots as ``robots``)."""
        from mrslam_core.slam.checkpoint import save_checkpoint

        extra: dict[str, Any] = {"robots": self.robots}
        for part, state in self.state().items():
            extra.update({f"{part}.{key}": value for key, value in state.items()})
        return save_checkpoint(self.slam, path, extra)

    @classmethod
    def resume(cls, cfg: CentralConfig, path: str | Path) -> CentralMapper:
        """A mapper in the state :meth:`save` wrote (or a version 2 checkpoint held), continuing
        under ``cfg`` (same robots).

        Raises:
            CheckpointError: unreadable, or saved for other robots.
        """
        from mrslam_core.slam.checkpoint import CheckpointError, load_checkpoint

        slam, extra = load_checkpoint(path)
        robots, states = _saved_states(extra, slam)
        if robots is None or list(robots) != list(cfg.robots):
            raise CheckpointError(f"{path}: saved for robots {robots}, not {list(cfg.robots)}")
        mapper = cls(cfg)
        mapper.slam = slam
        try:
            mapper._load_state(states)
        except KeyError as exc:
            raise CheckpointError(f"{path}: the mapper's state lacks {exc}") from exc
        return mapper


def _saved_states(extra: dict[str, Any],
                  slam: MultiRobotFastSLAM) -> tuple[list[str] | None, dict[str, dict[str, Any]]]:
    """(robots, each part's state) of a checkpoint's ``extra`` values beside its filter ``slam``:
    by ``<part>.`` prefix; in a version 2 file, one flat state (JSON values under ``mapper``,
    arrays beside it) in which every part finds its values under the names it uses today, the
    queue without arrival numbers and, in the oldest, no list of unmerged robots (those not in
    the filter)."""
    legacy = extra.get("mapper")
    if isinstance(legacy, dict):
        flat = {**legacy, **{k: v for k, v in extra.items() if k != "mapper"}}
        flat["queue"] = [[robot, stamp, i] for i, (robot, stamp) in enumerate(flat.get("queue", []))]
        flat.setdefault("unmerged", [r for r in legacy.get("robots", []) if r not in slam.index])
        return legacy.get("robots"), {part: flat for part in PARTS}
    return extra.get("robots"), {part: {key[len(part) + 1:]: value for key, value in extra.items()
                                        if key.startswith(f"{part}.")} for part in PARTS}
