"""Value objects passed between the frontend, the filter and the tools."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class ObservationSet:
    """What one robot's sensor saw at one instant.

    Attributes:
        robot: robot name (e.g. ``"robot1"``).
        stamp_ns: time of the images / measurement (ns).
        z: (B, dim) measurements in the robot's base_link frame. For the stereo model, 3D points
            (x forward, y left, z up) [m]; for the range-bearing model, (range [m], bearing [rad]).
        cov: (B, dim, dim) measurement covariances, same units squared.
        descriptors: (B, D) float32 appearance descriptors (D may be 0: no descriptor).
        track_ids: (B,) int64 frontend track ids (-1 where unknown).
        sightings: the other robots measured at the same instant (each ``observer`` is
            ``robot``); scored in the particle weights, not mapped. A set may hold sightings and
            no landmark measurements (B = 0), or neither (the robot's motion up to ``stamp_ns``).

    Raises:
        ValueError: arrays of inconsistent shapes, or a sighting by another robot.
    """

    robot: str
    stamp_ns: int
    z: np.ndarray
    cov: np.ndarray
    descriptors: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), np.float32))
    track_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    sightings: tuple[RobotSighting, ...] = ()

    def __post_init__(self) -> None:
        z = np.asarray(self.z, dtype=float)
        if z.ndim != 2:
            raise ValueError(f"z must be (B, dim), got shape {z.shape}")
        b, dim = z.shape
        cov = np.asarray(self.cov, dtype=float)
        if cov.shape != (b, dim, dim):
            raise ValueError(f"cov must be {(b, dim, dim)}, got {cov.shape}")
        desc = np.asarray(self.descriptors, dtype=np.float32)
        if desc.size == 0:
            desc = np.zeros((b, 0), np.float32)
        if desc.ndim != 2 or desc.shape[0] != b:
            raise ValueError(f"descriptors must be (B={b}, D), got {desc.shape}")
        tid = np.asarray(self.track_ids, dtype=np.int64)
        if tid.size == 0:
            tid = np.full(b, -1, np.int64)
        if tid.shape != (b,):
            raise ValueError(f"track_ids must be ({b},), got {tid.shape}")
        object.__setattr__(self, "z", z)
        object.__setattr__(self, "cov", cov)
        object.__setattr__(self, "descriptors", desc)
        object.__setattr__(self, "track_ids", tid)
        sightings = tuple(self.sightings)
        for s in sightings:
            if s.observer != self.robot:
                raise ValueError(f"a sighting by {s.observer!r} in a set of {self.robot!r}")
        object.__setattr__(self, "sightings", sightings)

    def __len__(self) -> int:
        return self.z.shape[0]


@dataclass(frozen=True)
class RobotSighting:
    """A measurement of another robot (range-bearing), scored in the particle weight.

    Attributes:
        observer: name of the robot that measured.
        target: name of the robot that was measured.
        z: (2,) range [m], bearing [rad] in the observer's base_link.
        cov: (2, 2) covariance.
    """

    observer: str
    target: str
    z: np.ndarray
    cov: np.ndarray
