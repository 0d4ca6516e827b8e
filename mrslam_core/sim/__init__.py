"""A headless pybullet world with Pioneer 3-DX robots carrying stereo cameras (no ROS)."""

from mrslam_core.sim.errors import SimError

__all__ = ["SimError"]
