"""How much of a world a team's occupancy grid has seen."""

from __future__ import annotations

import numpy as np


def explored_fraction(known: np.ndarray, origin: np.ndarray, resolution: float,
                      truth_free: np.ndarray, truth_resolution: float) -> float:
    """Share of the world's reachable free cells that the grid has observed.

    The grid and the world's raster need not match in extent or resolution (a growing grid
    covers what was seen, not the world): each world cell is looked up at its centre, and world
    cells off the grid count as not observed.

    Args:
        known: (H, W) bool, grid cells observed (row = y, column = x).
        origin: (2,) or (3,) map-frame position [m] of the grid's cell (0, 0) corner (yaw ignored).
        resolution: grid cell size [m].
        truth_free: (h, w) bool, the world's reachable free cells, cell (0, 0) at the map origin.
        truth_resolution: their cell size [m].
    """
    known = np.asarray(known, bool)
    h, w = truth_free.shape
    yy, xx = np.mgrid[0:h, 0:w]
    x = (xx + 0.5) * truth_resolution
    y = (yy + 0.5) * truth_resolution
    i = np.floor((y - origin[1]) / resolution).astype(np.int64)
    j = np.floor((x - origin[0]) / resolution).astype(np.int64)
    inside = (i >= 0) & (i < known.shape[0]) & (j >= 0) & (j < known.shape[1])
    seen = np.zeros((h, w), bool)
    seen[inside] = known[i[inside], j[inside]]
    return float((seen & truth_free).sum() / max(int(truth_free.sum()), 1))
