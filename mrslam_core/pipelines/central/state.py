"""Observation sets in a part's checkpoint state: their arrays by name, robot and stamp beside."""

from __future__ import annotations

from typing import Any

import numpy as np

from mrslam_core.types import ObservationSet


def sets_state(name: str, sets: list[ObservationSet]) -> dict[str, np.ndarray]:
    """The arrays of ``sets`` as ``{name}_z_{i}`` (B, dim), ``{name}_cov_{i}`` (B, dim, dim),
    ``{name}_desc_{i}`` (B, D) and ``{name}_tracks_{i}`` (B,), i the set's position in ``sets``
    (the caller keeps each set's robot and stamp)."""
    out: dict[str, np.ndarray] = {}
    for i, o in enumerate(sets):
        out.update({f"{name}_z_{i}": o.z, f"{name}_cov_{i}": o.cov, f"{name}_desc_{i}": o.descriptors,
                    f"{name}_tracks_{i}": o.track_ids})
    return out


def set_from_state(state: dict[str, Any], name: str, i: int, robot: str, stamp_ns: int) -> ObservationSet:
    """Set ``i`` of :func:`sets_state`, taken by ``robot`` at ``stamp_ns`` [ns]."""
    return ObservationSet(robot, int(stamp_ns), state[f"{name}_z_{i}"], state[f"{name}_cov_{i}"],
                          state[f"{name}_desc_{i}"], state[f"{name}_tracks_{i}"])
