"""Errors of the simulator package."""


class SimError(ValueError):
    """A world file, robot name, command or configuration the simulator cannot use."""
