"""Frontier cells (free cells next to unknown ones), grouped into frontiers."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from mrslam_core.arrays import unique_rows

_EIGHT = np.ones((3, 3), bool)


def frontier_cells(free: np.ndarray, known: np.ndarray) -> np.ndarray:
    """(H, W) bool: free cells with at least one unknown 8-neighbour."""
    unknown = ~known
    near_unknown = ndimage.binary_dilation(unknown, structure=_EIGHT)
    return free & near_unknown


def frontier_groups(frontier: np.ndarray, min_cells: int) -> list[np.ndarray]:
    """8-connected groups of frontier cells with at least ``min_cells``; each (n, 2) (row, col)."""
    labels, n = ndimage.label(frontier, structure=_EIGHT)
    groups = []
    for lab in range(1, n + 1):
        cells = np.argwhere(labels == lab)
        if len(cells) >= min_cells:
            groups.append(cells)
    return groups


def frontier_targets(groups: list[np.ndarray], stride: int) -> np.ndarray:
    """Candidate target cells (T, 2): every frontier's cell nearest its centroid, plus cells
    spaced about ``stride`` cells apart along large frontiers (so two robots can split one)."""
    out = []
    for cells in groups:
        centre = cells.mean(axis=0)
        out.append(cells[np.argmin(((cells - centre) ** 2).sum(1))])
        if len(cells) > 2 * stride:
            coarse = unique_rows(cells // stride, return_index=True)[1]
            out.extend(cells[coarse])
    return unique_rows(np.array(out, dtype=np.int64).reshape(-1, 2))


def standing_cells(targets: np.ndarray, passable: np.ndarray, reach_cells: float) -> np.ndarray:
    """Where a robot stands to look at each target: the passable cell nearest it.

    A frontier cell beside a wall, or amid the scattered hits of a stereo camera's far range,
    lies inside the inflated obstacles; its frontier is still worth a visit from the nearest cell
    a robot can stand on.

    Args:
        targets: (T, 2) target cells (row, col).
        passable: (H, W) bool, cells a robot may stand on.
        reach_cells: the standing cell may be at most this far from its target [cells].

    Returns:
        (T', 2) the standing cells of the targets that have one within reach, in the targets'
        order, each once.
    """
    targets = np.asarray(targets, np.int64).reshape(-1, 2)
    if not len(targets) or not passable.any():
        return np.zeros((0, 2), np.int64)
    dist, (rows, cols) = ndimage.distance_transform_edt(~passable, return_indices=True)
    r, c = targets[:, 0], targets[:, 1]
    cells = np.stack([rows[r, c], cols[r, c]], axis=1)[dist[r, c] <= reach_cells]
    if not len(cells):
        return cells
    return cells[np.sort(unique_rows(cells, return_index=True)[1])]
