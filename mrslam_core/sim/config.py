"""Configuration of the simulator (the only place its defaults are written)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from mrslam_core.sim.errors import SimError


@dataclass(frozen=True)
class StereoCameraConfig:
    """The stereo head: two identical, already rectified pinhole cameras side by side.

    The head looks along base_link's x axis; the left optical centre is at
    (mount_x, +baseline/2, mount_z) in base_link, the right one at (mount_x, −baseline/2, mount_z).

    Attributes:
        width, height: image size [px].
        hfov_deg: horizontal field of view [deg]; square pixels, so fy = fx.
        baseline: distance between the optical centres [m].
        mount_x: optical centres ahead of base_link [m].
        mount_z: optical centres above the floor (base_link is on the floor) [m].
        rate_hz: stereo pairs per simulated second.
        near, far: clipping planes of the renderer [m]; depth beyond ``far`` reads as ``far``.
        encoding: ``mono8`` (H, W) or ``rgb8`` (H, W, 3) images.
        supersample: render at this many times the resolution and average blocks down
            (anti-aliasing: TinyRenderer samples textures at one point per pixel, which makes
            stereo disparities jump in whole texels); costs supersample² in rendering time.
    """

    width: int = 320
    height: int = 240
    hfov_deg: float = 70.0
    baseline: float = 0.12
    mount_x: float = 0.12
    mount_z: float = 0.45
    rate_hz: float = 5.0
    near: float = 0.05
    far: float = 30.0
    encoding: Literal["mono8", "rgb8"] = "mono8"
    supersample: int = 1

    def __post_init__(self) -> None:
        if self.width < 16 or self.height < 16 or not 10 < self.hfov_deg < 170:
            raise SimError("camera: need width, height >= 16 and 10 < hfov_deg < 170")
        if self.baseline <= 0 or self.rate_hz <= 0 or not 0 < self.near < self.far:
            raise SimError("camera: need baseline > 0, rate_hz > 0 and 0 < near < far")
        if not 0.3 < self.mount_z < 2.0 or abs(self.mount_x) > 0.3:
            raise SimError("camera: mount_z must be in (0.3, 2.0) m (above the body), |mount_x| <= 0.3 m")
        if not 1 <= self.supersample <= 4:
            raise SimError("camera: supersample must be 1..4")
        if self.encoding not in ("mono8", "rgb8"):
            raise SimError(f"camera: encoding must be mono8 or rgb8, got {self.encoding!r}")


@dataclass(frozen=True)
class DriveConfig:
    """Differential drive of a Pioneer 3-DX.

    Attributes:
        max_speed: |v| limit [m/s].
        max_turn_rate: |ω| limit [rad/s].
        max_accel: |dv/dt| limit [m/s²].
        max_turn_accel: |dω/dt| limit [rad/s²].
        track: distance between the wheel contact points [m].
        wheel_radius: [m].
    """

    max_speed: float = 0.6
    max_turn_rate: float = 1.5
    max_accel: float = 1.0
    max_turn_accel: float = 3.0
    track: float = 0.33
    wheel_radius: float = 0.0975

    def __post_init__(self) -> None:
        if min(self.max_speed, self.max_turn_rate, self.max_accel, self.max_turn_accel) <= 0:
            raise SimError("drive: speed, turn rate and acceleration limits must be > 0")
        if self.track <= 0 or self.wheel_radius <= 0:
            raise SimError("drive: track and wheel_radius must be > 0")


@dataclass(frozen=True)
class OdometryNoiseConfig:
    """Wheel-odometry errors, systematic and random.

    Systematic (constant over a run): each wheel's travelled distance is scaled by
    (1 + scale_error_{left,right}) and the odometry assumes a track (1 + track_error) times the
    true one.

    Random (zero mean, independent per physics step, variance proportional to the motion so the
    statistics do not depend on the step rate): 002 Table I adds N(0, (0.05·d)²) to x and to y and
    N(0, (3°)²) to the heading for each grid step of d = 0.5 m. Per metre that is
    translation_var_per_m = 0.05² · 0.5 and heading_var_per_m = (3°)² / 0.5; turning on the spot
    adds heading_var_per_rad (3° per quarter turn). The translation noise is applied along and
    across the direction of travel in base_link, as the paper's x and y noise.

    Attributes:
        scale_error_left, scale_error_right: relative wheel-distance errors [-].
        track_error: relative error of the track the odometry assumes [-].
        translation_var_per_m: variance of each translation component per metre travelled [m²/m].
        heading_var_per_m: heading variance per metre travelled [rad²/m].
        heading_var_per_rad: heading variance per radian turned [rad²/rad].
    """

    scale_error_left: float = 0.005
    scale_error_right: float = -0.005
    track_error: float = 0.01
    translation_var_per_m: float = 1.25e-3
    heading_var_per_m: float = 5.483e-3
    heading_var_per_rad: float = 1.745e-3

    def __post_init__(self) -> None:
        if min(self.translation_var_per_m, self.heading_var_per_m, self.heading_var_per_rad) < 0:
            raise SimError("odometry: noise variances must be >= 0")
        if self.track_error <= -1 or min(self.scale_error_left, self.scale_error_right) <= -1:
            raise SimError("odometry: relative errors must be > -1")


@dataclass(frozen=True)
class RouteConfig:
    """A closed loop of waypoints; empty: the robots follow their commands (cmd_vel).

    Attributes:
        waypoints: x0 y0 x1 y1 … in the map frame [m]; the loop closes from the last to the
            first, and every robot drives it in this order from the point of it nearest to it.
        speed: forward speed on the route [m/s].
        turn_rate: turn rate limit [rad/s].
        lookahead: pure-pursuit lookahead [m].
        start_interval: robot k (0-based) stands still until k · start_interval, so robots that
            start close together drive the loop apart (each would otherwise film the one ahead,
            a moving object, all the way) [s].
    """

    waypoints: tuple[float, ...] = ()
    speed: float = 0.3
    turn_rate: float = 0.5
    lookahead: float = 0.5
    start_interval: float = 0.0

    def __post_init__(self) -> None:
        if len(self.waypoints) % 2 or 0 < len(self.waypoints) < 6:
            raise SimError(f"route.waypoints: x y pairs of at least 3 points, got {len(self.waypoints)} numbers")
        if min(self.speed, self.turn_rate, self.lookahead) <= 0 or self.start_interval < 0:
            raise SimError("route: speed, turn_rate and lookahead must be > 0, start_interval >= 0")


@dataclass(frozen=True)
class SimConfig:
    """The simulation.

    Attributes:
        world: a built-in world name (``office``, ``small``, ``hall40x30``, ``ring24x16``,
            ``openplan18x14``, ``warehouse30x20``), a generated building ``gen:KIND:SEED[:STARTS[:ROBOTS]]``
            (KIND office, ring, open or warehouse; STARTS together or apart; see
            :mod:`mrslam_core.sim.worldgen`) or a path to a world YAML.
        physics_hz: physics steps per simulated second.
        seed: seeds the odometry noise and the procedural textures.
        texture_density: texels per metre on the floor, walls and furniture.
        laser_height: height of the ray-cast pseudo-laser above the floor [m].
        route: a loop the robots drive on their own (default: none, they follow commands).
    """

    world: str = "office"
    physics_hz: float = 50.0
    seed: int = 0
    texture_density: float = 128.0
    laser_height: float = 0.2
    camera: StereoCameraConfig = field(default_factory=StereoCameraConfig)
    drive: DriveConfig = field(default_factory=DriveConfig)
    odometry: OdometryNoiseConfig = field(default_factory=OdometryNoiseConfig)
    route: RouteConfig = field(default_factory=RouteConfig)

    def __post_init__(self) -> None:
        if self.physics_hz < 10:
            raise SimError("physics_hz must be >= 10")
        if not 8 <= self.texture_density <= 512:
            raise SimError("texture_density must be in [8, 512] texels per metre")
        if not 0 < self.laser_height < 2:
            raise SimError("laser_height must be in (0, 2) m")
