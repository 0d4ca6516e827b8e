"""Choosing points spread over the image: the detections of a frame and its B observations."""

from __future__ import annotations

import numpy as np


def select_spread(
    xy: np.ndarray, strength: np.ndarray, eligible: np.ndarray, k: int,
    width: int, height: int, cols: int, rows: int,
) -> np.ndarray:
    """Indices of at most k eligible points, spread over a cols × rows image grid.

    Round-robin over grid cells: every occupied cell gives its strongest point first, then its
    second strongest, and so on; within a round, stronger points come first.

    Args:
        xy: (N, 2) image positions (column, row) [px].
        strength: (N,) larger is better.
        eligible: (N,) bool.
        k: at most this many.
        width, height: image size [px].
        cols, rows: grid size.

    Returns:
        (≤ k,) int64 indices into the N points, in selection order.
    """
    idx = np.nonzero(eligible)[0]
    if idx.size <= k:
        return idx[np.argsort(-strength[idx], kind="stable")]
    cx = np.clip((xy[idx, 0] * cols // width).astype(np.int64), 0, cols - 1)
    cy = np.clip((xy[idx, 1] * rows // height).astype(np.int64), 0, rows - 1)
    cell = cy * cols + cx
    order = np.lexsort((-strength[idx], cell))  # by cell, strongest first within a cell
    cell_sorted = cell[order]
    first = np.r_[0, np.nonzero(np.diff(cell_sorted))[0] + 1]
    starts = np.repeat(first, np.diff(np.r_[first, cell_sorted.size]))
    rank = np.arange(cell_sorted.size) - starts  # rank within the cell
    pick = np.lexsort((-strength[idx][order], rank))[:k]
    return idx[order][pick]
