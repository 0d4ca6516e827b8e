"""Observation sets in a part's checkpoint state: their arrays by name, robot and stamp beside."""

from __future__ import annotations

from typing import Any

import numpy as np

from mrslam_core.types import ObservationSet, RobotSighting


def sets_state(name: str, sets: list[ObservationSet]) -> dict[str, Any]:
    """The arrays of ``sets`` as ``{name}_z_{i}`` (B, dim), ``{name}_cov_{i}`` (B, dim, dim),
    ``{name}_desc_{i}`` (B, D) and ``{name}_tracks_{i}`` (B,), i the set's position in ``sets``
    (the caller keeps each set's robot and stamp); a set with S sightings also
    ``{name}_sight_z_{i}`` (S, 2), ``{name}_sight_cov_{i}`` (S, 2, 2) and ``{name}_sight_to_{i}``
    (the S targets' names, a JSON list)."""
    out: dict[str, Any] = {}
    for i, o in enumerate(sets):
        out.update({f"{name}_z_{i}": o.z, f"{name}_cov_{i}": o.cov, f"{name}_desc_{i}": o.descriptors,
                    f"{name}_tracks_{i}": o.track_ids})
        if o.sightings:
            out.update({f"{name}_sight_z_{i}": np.array([s.z for s in o.sightings], float).reshape(-1, 2),
                        f"{name}_sight_cov_{i}": np.array([s.cov for s in o.sightings], float).reshape(-1, 2, 2),
                        f"{name}_sight_to_{i}": [s.target for s in o.sightings]})
    return out


def set_from_state(state: dict[str, Any], name: str, i: int, robot: str, stamp_ns: int) -> ObservationSet:
    """Set ``i`` of :func:`sets_state`, taken by ``robot`` at ``stamp_ns`` [ns]."""
    targets = state.get(f"{name}_sight_to_{i}", [])
    sightings = tuple(RobotSighting(robot, str(t), np.asarray(z, float), np.asarray(c, float))
                      for t, z, c in zip(targets, state.get(f"{name}_sight_z_{i}", []),
                                         state.get(f"{name}_sight_cov_{i}", [])))
    return ObservationSet(robot, int(stamp_ns), state[f"{name}_z_{i}"], state[f"{name}_cov_{i}"],
                          state[f"{name}_desc_{i}"], state[f"{name}_tracks_{i}"], sightings)
