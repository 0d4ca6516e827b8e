"""Configuration of the simulator (the only place its defaults are written)."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class StereoCameraConfig:
    """The stereo head: two identical pinhole cameras, the right one ``baseline`` to the right.

    Attributes:
        width, height: image size [px].
        hfov_deg: horizontal field of view [deg].
        baseline: distance between the optical centres [m].
        mount_x: camera centre ahead of base_link [m].
        mount_z: camera centre above the floor (base_link is on the floor) [m].
        rate_hz: stereo pairs per simulated second.
        near, far: clipping planes of the renderer [m].
    """

    width: int = 320
    height: int = 240
    hfov_deg: float = 70.0
    baseline: float = 0.12
    mount_x: float = 0.12
    mount_z: float = 0.45
    rate_hz: float = 2.0
    near: float = 0.05
    far: float = 30.0

    def __post_init__(self) -> None:
        if self.width < 16 or self.height < 16 or not 10 < self.hfov_deg < 170:
            raise ValueError("camera: need width, height >= 16 and 10 < hfov_deg < 170")
        if self.baseline <= 0 or self.rate_hz <= 0 or not 0 < self.near < self.far:
            raise ValueError("camera: need baseline > 0, rate_hz > 0 and 0 < near < far")


@dataclass(frozen=True)
class DriveConfig:
    """Differential drive limits of a Pioneer 3-DX (m/s, rad/s, m/s², rad/s²; track [m])."""

    max_speed: float = 0.6
    max_turn_rate: float = 1.5
    max_accel: float = 1.0
    max_turn_accel: float = 3.0
    track: float = 0.33
    wheel_radius: float = 0.0975


@dataclass(frozen=True)
class OdometryNoiseConfig:
    """Wheel-odometry errors (002 Table I kind: systematic and random).

    Systematic: each wheel's distance is scaled by (1 + scale_error_{left,right}) and the track
    the odometry assumes is off by ``track_error`` (relative). Random: each wheel's distance gets
    zero-mean Gaussian noise of variance ``k_wheel`` · |distance| [m²/m].
    """

    scale_error_left: float = 0.005
    scale_error_right: float = -0.005
    track_error: float = 0.01
    k_wheel: float = 2e-4


@dataclass(frozen=True)
class SimConfig:
    """The simulation.

    Attributes:
        world: a built-in world name (``office``, ``small``) or a path to a world YAML.
        physics_hz: physics steps per simulated second.
        seed: seeds odometry noise and procedural textures.
        texture_size: side of the generated texture images [px].
    """

    world: str = "office"
    physics_hz: float = 50.0
    seed: int = 0
    texture_size: int = 128
    camera: StereoCameraConfig = field(default_factory=StereoCameraConfig)
    drive: DriveConfig = field(default_factory=DriveConfig)
    odometry: OdometryNoiseConfig = field(default_factory=OdometryNoiseConfig)

    def __post_init__(self) -> None:
        if self.physics_hz < 10:
            raise ValueError("physics_hz must be >= 10")
