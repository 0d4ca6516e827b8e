"""Errors of the simulator package."""

from mrslam_core.errors import InputError


class SimError(InputError, ValueError):
    """A world file, robot name, command or configuration the simulator cannot use."""
