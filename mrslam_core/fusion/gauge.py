"""Holding the common frame at its posterior mean while the central map is empty (issue 8).

When only some robots know their start pose, the common map frame is whatever those robots'
dead reckoning makes of it until they map their first landmarks. Before that, every particle of
the central filter differs only in the motion noise it drew for those robots; once a landmark is
created, each particle's map inherits that particle's pose error, and no later measurement
(landmarks, sightings of robots merged later, map alignments) can tell those frames apart, since
each is self-consistent. Resampling then keeps one of them at random: the whole team's frame ends
up rotated by a sample of the pre-landmark heading spread (σ = 0.20 rad with the MR.CLAM
random walk 0.05 rad/√s after robot 1's 14.5 s without a landmark on dataset 6), not by its mean.

:func:`hold_gauge` removes that unobservable spread: while the filter holds no landmark, each
robot's poses are set to their weighted mean (its dead reckoning from the known start, corrected by
whatever sightings between known robots weighted) and motion noise not yet drawn
(``defer_motion_noise``) is discarded. The robots' drift covariances (re-localisation) are kept:
the pose error relative to the world is real, it is only not worth sampling into the frame.
"""

from __future__ import annotations

import numpy as np

from mrslam_core.geometry.se2 import pose_moments
from mrslam_core.slam.filter import MultiRobotFastSLAM


def map_is_empty(slam: MultiRobotFastSLAM) -> bool:
    """True when no particle of ``slam`` holds a landmark (each distinct chunk of the store
    visited once, not every particle's map: the mapper asks before every step)."""
    store = slam.landmarks
    return store.size == 0 or not bool(store.held().any())


def hold_gauge(slam: MultiRobotFastSLAM, robots: list[str] | None = None) -> bool:
    """Collapse the pose spread of ``robots`` onto its weighted mean while the map is empty.

    Args:
        slam: the central filter; modified in place (poses (M, K, 3), ``pending_cov``).
        robots: the robots whose start poses fix the frame (default: all). A robot joined by a
            rendezvous before the first landmark keeps its particles: their spread is the
            join's uncertainty relative to those robots, not the frame's.

    Returns:
        True if the poses were collapsed (the map was empty), False if nothing was changed.
    """
    if not map_is_empty(slam):
        return False
    ks = np.arange(len(slam.robots)) if robots is None else np.array([slam.index[r] for r in robots], np.int64)
    w = np.exp(slam.log_w)
    for k in ks.tolist():
        slam.poses[:, k] = pose_moments(slam.poses[:, k], w)[0]
        slam.pending_cov.pop(k, None)
    return True
