"""A headless pybullet world with Pioneer 3-DX robots carrying stereo cameras (no ROS).

``Simulation`` steps the world at a fixed physics rate, drives the robots from (v, ω) commands,
integrates noisy wheel odometry and renders stereo pairs with depth; ``load_world`` reads the
YAML worlds (``office``, ``small`` or a file).
"""

from mrslam_core.sim.config import DriveConfig, OdometryNoiseConfig, SimConfig, StereoCameraConfig
from mrslam_core.sim.errors import SimError
from mrslam_core.sim.simulation import Simulation, StereoFrame
from mrslam_core.sim.world import World, load_world

__all__ = ["DriveConfig", "OdometryNoiseConfig", "SimConfig", "SimError", "Simulation", "StereoCameraConfig",
           "StereoFrame", "World", "load_world"]
