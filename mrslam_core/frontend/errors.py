"""Exception types of the frontend package."""

from __future__ import annotations


class FrontendError(Exception):
    """Base class of the frontend's errors."""


class CameraModelError(FrontendError, ValueError):
    """Camera calibration that cannot describe a horizontal rectified stereo pair."""
