"""Fixtures of the core's tests."""

from __future__ import annotations

import pytest

from mrslam_core.exploration.config import GridConfig
from mrslam_core.exploration.grid import OccupancyGrid


@pytest.fixture
def wall_south():
    """A factory of grids 6 m × 4 m observed free, with a wall in the cells y 0.6–0.7 m along the
    whole width (a new grid each call: tests change them)."""

    def make() -> OccupancyGrid:
        grid = OccupancyGrid(GridConfig(resolution=0.1), extent=((0.0, 0.0), (6.0, 4.0)))
        grid.observed[:] = True
        grid.logodds[:] = -3.0
        grid.logodds[6, :] = 3.0
        return grid

    return make
