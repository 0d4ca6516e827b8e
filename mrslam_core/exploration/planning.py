"""A* paths on the grid with obstacles inflated by the robot radius, and a pure-pursuit follower."""

from __future__ import annotations

import heapq

import numpy as np
from scipy import ndimage

from mrslam_core.geometry.se2 import wrap_angle

_MOVES = [(-1, -1, 1.4142135623730951), (-1, 0, 1.0), (-1, 1, 1.4142135623730951), (0, -1, 1.0),
          (0, 1, 1.0), (1, -1, 1.4142135623730951), (1, 0, 1.0), (1, 1, 1.4142135623730951)]


def inflate(blocked: np.ndarray, radius_cells: float) -> np.ndarray:
    """Cells within ``radius_cells`` of a blocked cell (Euclidean distance transform)."""
    if not blocked.any():
        return blocked.copy()
    return ndimage.distance_transform_edt(~blocked) <= radius_cells


def astar(passable: np.ndarray, start: tuple[int, int], goal: tuple[int, int],
          cost: np.ndarray | None = None) -> list[tuple[int, int]] | None:
    """Shortest 8-connected path of cells from start to goal over ``passable`` (H, W) bool, with
    the octile distance as heuristic; None when the goal cannot be reached.

    ``cost`` (H, W), each >= 1: a step into a cell costs its length times the cell's cost
    (default 1 everywhere), so the heuristic stays admissible."""
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
                ng = gcost + (step if cost is None else step * cost[nr, nc])
                if ng < g[nr, nc]:
                    g[nr, nc] = ng
                    parent[nr, nc] = r * w + c
                    heapq.heappush(heap, (ng + heur(nr, nc), ng, nr, nc))
    return None


def pure_pursuit(pose: np.ndarray, path_xy: np.ndarray, lookahead: float, max_speed: float,
                 max_turn_rate: float, keep_arc: bool = False) -> tuple[float, float, int]:
    """(v [m/s], ω [rad/s], index of the path point aimed at) to follow ``path_xy`` (N, 2).

    Aims at the first path point at least ``lookahead`` away beyond the closest one; turns on the
    spot while that point is more than 60° off the heading. Where the arc to that point is tighter
    than ``max_speed / max_turn_rate``, the turn rate is clipped and the robot swings wide (0.7 m
    radius at 0.35 m/s and 0.5 rad/s); with ``keep_arc`` the speed is lowered instead so that it
    drives that arc (regulated pure pursuit).
    """
    d = np.linalg.norm(path_xy - pose[:2], axis=1)
    nearest = int(np.argmin(d))
    ahead = np.flatnonzero(d[nearest:] >= lookahead)
    idx = nearest + int(ahead[0]) if ahead.size else len(path_xy) - 1
    dx, dy = path_xy[idx] - pose[:2]
    bearing = float(wrap_angle(np.arctan2(dy, dx) - pose[2]))
    dist = float(np.hypot(dx, dy))
    if abs(bearing) > np.pi / 3:
        return 0.0, float(np.clip(2.0 * bearing, -max_turn_rate, max_turn_rate)), idx
    v = max_speed * min(1.0, dist / max(lookahead, 1e-6)) * np.cos(bearing)
    curvature = 2.0 * np.sin(bearing) / max(dist, 1e-6)
    if keep_arc and abs(v * curvature) > max_turn_rate:
        v = max_turn_rate / abs(curvature)
    return float(v), float(np.clip(v * curvature, -max_turn_rate, max_turn_rate)), idx

