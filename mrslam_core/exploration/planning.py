"""A* paths on the grid with obstacles inflated by the robot radius."""

from __future__ import annotations

import heapq

import numpy as np
from scipy import ndimage

_MOVES = [(-1, -1, 1.4142135623730951), (-1, 0, 1.0), (-1, 1, 1.4142135623730951), (0, -1, 1.0),
          (0, 1, 1.0), (1, -1, 1.4142135623730951), (1, 0, 1.0), (1, 1, 1.4142135623730951)]


def inflate(blocked: np.ndarray, radius_cells: float) -> np.ndarray:
    """Cells within ``radius_cells`` of a blocked cell (Euclidean distance transform)."""
    if not blocked.any():
        return blocked.copy()
    return ndimage.distance_transform_edt(~blocked) <= radius_cells


def astar(passable: np.ndarray, start: tuple[int, int], goal: tuple[int, int]) -> list[tuple[int, int]] | None:
    """Shortest 8-connected path of cells from start to goal over ``passable`` (H, W) bool, with
    the octile distance as heuristic; None when the goal cannot be reached."""
    h, w = passable.shape
    if not (0 <= goal[0] < h and 0 <= goal[1] < w) or not passable[goal]:
        return None
    g = np.full((h, w), np.inf)
    parent = -np.ones((h, w), np.int64)
    g[start] = 0.0
    gr, gc = goal

    def heur(r: int, c: int) -> float:
        dr, dc = abs(r - gr), abs(c - gc)
        return max(dr, dc) + 0.41421356 * min(dr, dc)

    heap = [(heur(*start), 0.0, start[0], start[1])]
    closed = np.zeros((h, w), bool)
    while heap:
        _, gcost, r, c = heapq.heappop(heap)
        if closed[r, c]:
            continue
        closed[r, c] = True
        if (r, c) == goal:
            path = [(r, c)]
            while parent[path[-1]] >= 0:
                p = int(parent[path[-1]])
                path.append((p // w, p % w))
            return path[::-1]
        for dr, dc, step in _MOVES:
            nr, nc = r + dr, c + dc
            if 0 <= nr < h and 0 <= nc < w and passable[nr, nc] and not closed[nr, nc]:
                ng = gcost + step
                if ng < g[nr, nc]:
                    g[nr, nc] = ng
                    parent[nr, nc] = r * w + c
                    heapq.heappush(heap, (ng + heur(nr, nc), ng, nr, nc))
    return None
