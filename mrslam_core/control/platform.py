"""The robot platform the controller drives: body dimensions and speed limits."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class PlatformConfig:
    """A differential-drive robot as the path follower and the recovery see it. The defaults are
    the simulated Pioneer 3-DX (mrslam_core/sim/data/pioneer3dx.urdf: a 0.45 × 0.38 m body whose
    centre is 0.04 m behind the axle, so its corners are 0.33 m from it).

    Attributes:
        max_speed, max_turn_rate: the fastest the follower drives and turns [m/s, rad/s].
        bumper_range: distance ahead of the robot's centre (base_link) at which it touches
            what it drives into [m].
        rear: distance from the axle (base_link) back to the rear of the body [m].
    """

    max_speed: float = 0.5
    max_turn_rate: float = 1.2
    bumper_range: float = 0.3
    rear: float = 0.265

    def __post_init__(self) -> None:
        if not (self.max_speed > 0 and self.max_turn_rate > 0):
            raise ValueError("max_speed and max_turn_rate must be > 0")
