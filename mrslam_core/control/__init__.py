"""Drive commands of each robot: path following, turns on the spot and recovery, for a platform
described by :class:`~mrslam_core.control.platform.PlatformConfig` (no robot's numbers in code)."""
