"""The robot platform the controller drives: footprint, camera near limit, speed limits."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PlatformConfig:
    """A differential-drive robot with a forward-looking stereo camera, as the path follower,
    the recovery and the exploration see it. The defaults are the simulated Pioneer 3-DX: the
    simulator builds its body from this footprint (``mrslam_core.sim.robot.robot_description``
    fills the body box of mrslam_core/sim/data/pioneer3dx.urdf from it), with the simulated
    team's stereo head (config/sim_team.yaml).

    The footprint is a rectangle in base_link (x forward, y left; base_link midway between the
    drive wheels): from ``-rear`` to ``front`` along x and ``±width / 2`` along y.

    Attributes:
        max_speed, max_turn_rate: the fastest the follower drives and turns [m/s, rad/s].
        front: distance from the axle (base_link) forward to the front of the body [m].
        rear: distance from the axle (base_link) back to the rear of the body [m].
        width: the body's width [m].
        camera_near: the camera's near limit, from base_link: obstacles nearer than this ahead
            of the axle are not seen (a stereo head sees nothing nearer than f·b / its largest
            disparity, from the cameras, which sit ahead of the axle). The simulated head: 0.12 m
            ahead of the axle + 228.5 px · 0.12 m / 128 px = 0.334 m [m].
    """

    max_speed: float = 0.5
    max_turn_rate: float = 1.2
    front: float = 0.185
    rear: float = 0.265
    width: float = 0.38
    camera_near: float = 0.34

    def __post_init__(self) -> None:
        if not (self.max_speed > 0 and self.max_turn_rate > 0):
            raise ValueError("max_speed and max_turn_rate must be > 0")
        if not (self.front > -self.rear and self.width > 0):
            raise ValueError(f"the footprint needs front > -rear and width > 0, got front {self.front}, "
                             f"rear {self.rear}, width {self.width}")
        if not self.camera_near >= 0:
            raise ValueError("camera_near must be >= 0")

    @property
    def corner_radius(self) -> float:
        """How far the body reaches from base_link (its farthest corner) [m]: the circle its
        corners sweep turning on the spot."""
        return float(np.hypot(max(abs(self.front), abs(self.rear)), self.width / 2))

    @property
    def length(self) -> float:
        """The body's length, ``front + rear`` [m]."""
        return self.front + self.rear

    @property
    def centre_x(self) -> float:
        """The body's centre ahead of base_link, ``(front - rear) / 2`` [m]."""
        return (self.front - self.rear) / 2
