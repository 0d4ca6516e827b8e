"""Configuration of the drive commands: path following, turns on the spot, recovery (the only
place their defaults are written)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mrslam_core.control.platform import PlatformConfig


@dataclass(frozen=True)
class ControlConfig:
    """How each robot follows its path and frees itself (:class:`~mrslam_core.control.controller.Controller`).

    Attributes:
        platform: the robot driven (footprint, camera near limit, speed limits).
        lookahead: pure-pursuit lookahead distance [m].
        keep_arc: where the pure-pursuit arc is tighter than ``max_speed / max_turn_rate``,
            slow down to drive it instead of clipping the turn rate and swinging wide (see
            :func:`~mrslam_core.control.pursuit.pure_pursuit`; measured in docs/results.md:
            fewer collisions with door frames but less area explored at first; later, on in the
            team defaults: more explored and no robot lost over 9 fresh seeds).
        open_side_turns: a turn on the spot of more than ``open_side_turn`` goes the long way
            round when the short way sweeps the robot's heading past an occupied cell nearer than
            ``open_side_near`` and the long way keeps ``open_side_gain`` further from any: a
            stereo camera facing a wall nearer than its near limit sees nothing, and a robot that
            turned blind beside a wall came out 5-7° off in the recorded demos traced; counted as
            ``long_turns``. On in the team defaults: lower ATE, less explored (docs/results.md).
        open_side_turn: see ``open_side_turns`` [rad] (120°).
        open_side_near, open_side_gain: see ``open_side_turns`` [m].
        turn_clearance: before a turn on the spot whose headings come nearer than this [m] to an
            occupied cell (rays from the robot's centre), the robot first backs straight away at
            ``recovery_speed``, in steps of ``back_step`` up to ``back_max`` and only where the
            space behind is free, until they no longer do; a turn already begun is not checked
            again (0: off; else at least the platform's ``camera_near``: a turn whose headings
            pass a wall nearer than that is blind). Counted as ``turn_backoffs``. On in the team
            defaults at 0.6 m: with ``turn_stall_time``, 2 of 78 robots above 0.10 m over 26
            closed-loop seeds against 7 of 78 without (docs/results.md).
        back_max, back_step: see ``turn_clearance`` [m].
        back_fan, back_margin: the robot backs only as far as the fan of ±``back_fan`` [rad]
            (35°) behind its axle is free of occupied cells to the platform's ``rear`` plus
            ``back_margin`` [m] beyond the distance backed.
        turn_stall_time: a robot turning on the spot whose heading moved less than
            ``turn_stall_angle`` in this long is against something (a door jamb, a teammate: the
            body's corners swing out to the platform's ``corner_radius``) and turns the other
            way round instead, once per turn; counted as ``blocked_turns`` (0: off) [s].
        turn_stall_angle: see ``turn_stall_time`` [rad] (5°).
        recovery_time, recovery_speed: a robot that made no headway (or can reach no target from
            where it stands: ``boxed_in``) drives straight this long at this speed before its next
            goal, backward, or forward when its last recovery did not move it (a wedged robot
            frees itself) [s, m/s]; ``recovery_speed`` is also the speed of backing away before
            a turn.
    """

    platform: PlatformConfig = field(default_factory=PlatformConfig)
    lookahead: float = 0.4
    keep_arc: bool = False
    open_side_turns: bool = False
    open_side_turn: float = float(np.radians(120.0))
    open_side_near: float = 0.6
    open_side_gain: float = 0.2
    turn_clearance: float = 0.0
    back_max: float = 0.4
    back_step: float = 0.1
    back_fan: float = float(np.radians(35.0))
    back_margin: float = 0.1
    turn_stall_time: float = 1.5
    turn_stall_angle: float = float(np.radians(5.0))
    recovery_time: float = 2.0
    recovery_speed: float = 0.15

    def __post_init__(self) -> None:
        if not self.turn_clearance >= 0.0:
            raise ValueError("turn_clearance must be >= 0")
        if not (self.back_step > 0 and self.recovery_speed > 0):
            raise ValueError("back_step and recovery_speed must be > 0")
        if 0.0 < self.turn_clearance < self.platform.camera_near:
            raise ValueError(f"turn_clearance {self.turn_clearance} m is inside the camera's near limit "
                             f"(platform.camera_near {self.platform.camera_near} m): a turn that near is blind")
