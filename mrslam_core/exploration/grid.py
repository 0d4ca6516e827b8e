"""Log-odds occupancy grid built from 2D scans (pseudo laser from stereo, or a laser).

Cells are indexed (row, col) = (iy, ix): cell (i, j) covers x ∈ [ox + j·res, ox + (j+1)·res),
y ∈ [oy + i·res, oy + (i+1)·res) in the map frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mrslam_core.arrays import unique_rows
from mrslam_core.exploration.config import GridConfig


@dataclass
class Scan:
    """One scan in the robot frame: bearings (N,) [rad], ranges (N,) [m], hit (N,) bool (False:
    the beam reached max range and only proves free space)."""

    bearings: np.ndarray
    ranges: np.ndarray
    hit: np.ndarray

    @classmethod
    def from_obstacle_scan(cls, scan) -> "Scan":
        """From the stereo frontend's pseudo laser scan (mrslam_core.frontend.obstacles.ObstacleScan):
        a bin with an obstacle ends in a hit at its range; a bin without one proves free space up
        to its known-free range; bins with nothing known are left out."""
        n = scan.ranges.size
        bearings = scan.angle_min + (np.arange(n) + 0.5) * scan.angle_increment
        hit = np.isfinite(scan.ranges) & (scan.ranges <= scan.range_max)
        ranges = np.where(hit, scan.ranges, np.minimum(scan.free_ranges, scan.range_max))
        keep = hit | (ranges > 0)
        return cls(bearings[keep], ranges[keep], hit[keep])

    def without_hits_near(self, pose: np.ndarray, points: np.ndarray, radius: float) -> "Scan":
        """This scan, taken at ``pose`` (x, y, θ) map frame, with every hit ending within ``radius``
        [m] of one of ``points`` (K, 2) map frame turned into a free beam of the same range."""
        points = np.asarray(points, float).reshape(-1, 2)
        if radius <= 0 or not len(points) or not self.hit.any():
            return self
        pose = np.asarray(pose, float)
        ang = pose[2] + self.bearings
        end = pose[:2] + self.ranges[:, None] * np.column_stack([np.cos(ang), np.sin(ang)])
        near = np.linalg.norm(end[:, None] - points[None], axis=2).min(axis=1) < radius
        return Scan(self.bearings, self.ranges, self.hit & ~near)


class OccupancyGrid:
    """Log-odds grid (H, W) float32; probability = 1 / (1 + exp(−log-odds)); 0.5 = unknown."""

    def __init__(self, cfg: GridConfig | None = None):
        self.cfg = cfg or GridConfig()
        self.res = self.cfg.resolution
        self.origin = np.asarray(self.cfg.origin, float)
        self.shape = (int(np.ceil(self.cfg.size[1] / self.res)), int(np.ceil(self.cfg.size[0] / self.res)))
        self.logodds = np.zeros(self.shape, np.float32)
        self.observed = np.zeros(self.shape, bool)

    def cell_of(self, xy: np.ndarray) -> np.ndarray:
        """Map points (..., 2) [m] -> integer cells (..., 2) as (row, col)."""
        ij = np.floor((np.asarray(xy)[..., ::-1] - self.origin[::-1]) / self.res).astype(np.int64)
        return ij

    def centre_of(self, cells: np.ndarray) -> np.ndarray:
        """Cells (..., 2) (row, col) -> their centres (..., 2) (x, y) [m]."""
        return (np.asarray(cells)[..., ::-1] + 0.5) * self.res + self.origin

    def inside(self, cells: np.ndarray) -> np.ndarray:
        return (cells[..., 0] >= 0) & (cells[..., 0] < self.shape[0]) & (cells[..., 1] >= 0) & (cells[..., 1] < self.shape[1])

    def probability(self) -> np.ndarray:
        """(H, W) occupancy probability; unobserved cells are exactly 0.5."""
        return 1.0 / (1.0 + np.exp(-self.logodds))

    def free(self) -> np.ndarray:
        return self.observed & (self.probability() < self.cfg.free_below)

    def occupied(self) -> np.ndarray:
        return self.observed & (self.probability() > self.cfg.occupied_above)

    def insert(self, pose: np.ndarray, scan: Scan, teammates: np.ndarray | None = None) -> None:
        """Trace each beam from the robot at ``pose`` (x, y, θ) map frame: cells passed get
        ``miss``, the end cell of a hit ``hit``; hits on ``teammates`` (K, 2) [m], the other
        robots' positions, mark no obstacle (``teammate_radius``).

        Vectorised over beams: points are sampled along every beam at half a cell apart.
        """
        pose = np.asarray(pose, float)
        if teammates is not None:
            scan = scan.without_hits_near(pose, teammates, self.cfg.teammate_radius)
        ang = pose[2] + scan.bearings
        steps = np.arange(0.0, float(scan.ranges.max(initial=0.0)), self.res / 2)
        if steps.size == 0:
            return
        rr = np.minimum(steps[None, :], scan.ranges[:, None])
        pts = pose[None, None, :2] + rr[..., None] * np.stack([np.cos(ang), np.sin(ang)], -1)[:, None, :]
        cells = self.cell_of(pts)
        end = self.cell_of(pose[:2] + scan.ranges[:, None] * np.column_stack([np.cos(ang), np.sin(ang)]))
        free_mask = self.inside(cells) & (steps[None, :] < scan.ranges[:, None] - self.res / 2)
        free_cells = unique_rows(cells[free_mask])
        hit_cells = unique_rows(end[scan.hit & self.inside(end)])
        if free_cells.size:
            keep = np.ones(len(free_cells), bool)
            if hit_cells.size:  # a cell holding an obstacle end is not cleared by other beams
                keyf = free_cells[:, 0] * self.shape[1] + free_cells[:, 1]
                keyh = hit_cells[:, 0] * self.shape[1] + hit_cells[:, 1]
                keep = ~np.isin(keyf, keyh)
            fc = free_cells[keep]
            self.logodds[fc[:, 0], fc[:, 1]] += self.cfg.miss
            self.observed[free_cells[:, 0], free_cells[:, 1]] = True
        if hit_cells.size:
            self.logodds[hit_cells[:, 0], hit_cells[:, 1]] += self.cfg.hit
            self.observed[hit_cells[:, 0], hit_cells[:, 1]] = True
        np.clip(self.logodds, -self.cfg.clamp, self.cfg.clamp, out=self.logodds)


@dataclass
class ScanStore:
    """Scans kept in their robots' frames, so the grid can be rebuilt at new poses (e.g. when the
    SLAM filter's best particle changes)."""

    scans: list[tuple[str, int, Scan]] = field(default_factory=list)

    def add(self, robot: str, stamp_ns: int, scan: Scan) -> None:
        self.scans.append((robot, stamp_ns, scan))

    def rebuild(self, cfg: GridConfig, pose_of) -> OccupancyGrid:
        """A new grid from every stored scan at ``pose_of(robot, stamp_ns)`` -> (3,) or None."""
        grid = OccupancyGrid(cfg)
        for robot, stamp, scan in self.scans:
            pose = pose_of(robot, stamp)
            if pose is not None:
                grid.insert(pose, scan)
        return grid
