"""A headless pybullet world with Pioneer 3-DX robots carrying stereo cameras (no ROS).

``Simulation`` steps the world at a fixed physics rate, drives the robots from (v, ω) commands,
integrates noisy wheel odometry and renders stereo pairs with depth; ``load_world`` reads the
YAML worlds (built-in ones such as ``office``, a file, or a ``gen:KIND:SEED`` building from
:mod:`~mrslam_core.sim.worldgen`) and checks them.
"""

from mrslam_core.sim.config import DriveConfig, OdometryNoiseConfig, SimConfig, StereoCameraConfig
from mrslam_core.sim.errors import SimError
from mrslam_core.sim.simulation import Simulation, StereoFrame
from mrslam_core.sim.world import World, load_world

__all__ = ["DriveConfig", "OdometryNoiseConfig", "SimConfig", "SimError", "Simulation", "StereoCameraConfig",
           "StereoFrame", "World", "load_world"]
