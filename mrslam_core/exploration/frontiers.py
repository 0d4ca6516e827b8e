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

