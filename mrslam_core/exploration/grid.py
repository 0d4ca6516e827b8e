"""Log-odds occupancy grid built from 2D scans (pseudo laser from stereo, or a laser), growing
with what the scans reach.

Cells are indexed (row, col) = (iy, ix): cell (i, j) covers x ∈ [ox + j·res, ox + (j+1)·res),
y ∈ [oy + i·res, oy + (i+1)·res) in the map frame, (ox, oy) the grid's current origin.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import special

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
    """Log-odds occupancy grid that grows with what the robots see.

    The map frame's floor is cut into square cells of side ``res`` on one fixed lattice: world
    cell (I, J) = (⌊y / res⌋, ⌊x / res⌋) covers x ∈ [J·res, (J+1)·res), y ∈ [I·res, (I+1)·res).
    The grid holds a dense window of that lattice, the arrays

    - ``logodds`` (H, W) float32: probability = 1 / (1 + exp(−log-odds)); 0 (p = 0.5) = unknown;
    - ``observed`` (H, W) bool: cells a beam reached at least once (or a bumper touched);
    - ``contact`` (H, W) bool: cells a robot's bumper touched (:meth:`touch`), occupied for good,

    whose cell (i, j) (row = y, column = x) is world cell (i + ``offset[0]``, j + ``offset[1]``):
    it covers x ∈ [ox + j·res, ox + (j+1)·res), y ∈ [oy + i·res, oy + (i+1)·res) with
    (ox, oy) = :attr:`origin`.

    Growth. :meth:`insert` first makes room for every cell the scan marks: the hit cells, and
    the cells a beam passed with their 8 neighbours (so a free cell at the edge of what was seen
    still borders an unknown cell on the grid: a frontier; beyond the arrays nothing is looked
    at). A side that must move goes out to the next multiple of ``block`` cells of the lattice
    (``GridConfig.block``), the other sides stay; the arrays are re-allocated and the old ones
    copied into place. A world point keeps its world cell and its values; only its array index
    changes with ``offset``, so anything kept across calls must be kept in metres (the explorer
    keeps targets and paths in metres), or converted with :meth:`cell_of` on the grid as it is
    now. The grid never shrinks.

    Memory. Started empty, the arrays are the bounding box of the observed cells (grown by one
    cell where a beam passed) rounded out to the block lattice: per axis at most (extent of the
    observed cells + 2 blocks) cells, 5 bytes per cell (the 40 × 30 m hall40x30 world scanned
    all over at 0.1 m: 320 × 410 cells, 0.66 MB). A dense bounding box rather than a hash of
    tiles that exist only where something was seen: every consumer (frontiers, inflation by
    distance transform, travel cost by Dijkstra, A*) needs a dense (H, W) array of the explored
    area, which a tiled store would assemble at each call; and for a building the bounding box
    of what was seen is about its footprint.
    """

    def __init__(self, cfg: GridConfig | None = None,
                 extent: tuple[tuple[float, float], tuple[float, float]] | None = None):
        """An empty grid, or one allocated on ``extent`` = ((x_min, y_min), (x_max, y_max)) [m]
        rounded out to the cell lattice (not to blocks; for grids prepared by hand, and callers
        that know the area ahead)."""
        self.cfg = cfg or GridConfig()
        self.res = self.cfg.resolution
        self.block_cells = int(round(self.cfg.block / self.res))
        shape = (0, 0)
        #: (row, col) world cell of the arrays' cell (0, 0)
        self.offset = np.zeros(2, np.int64)
        if extent is not None:
            (x0, y0), (x1, y1) = extent
            lo = np.floor(np.array([y0, x0]) / self.res + 1e-9).astype(np.int64)
            hi = np.ceil(np.array([y1, x1]) / self.res - 1e-9).astype(np.int64)
            shape = tuple(int(n) for n in np.maximum(hi - lo, 0))
            self.offset = lo
        self.logodds = np.zeros(shape, np.float32)
        self.observed = np.zeros(shape, bool)
        #: (H, W) bool: cells a robot's bumper touched (:meth:`touch`): occupied for good
        self.contact = np.zeros(shape, bool)

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the arrays now (they grow)."""
        return self.logodds.shape

    @property
    def origin(self) -> np.ndarray:
        """(x, y) [m] map frame of the arrays' cell (0, 0) lower-left corner now (a new array)."""
        return self.offset[::-1] * self.res

    def _world_cells(self, xy: np.ndarray) -> np.ndarray:
        """Map points (..., 2) (x, y) [m] -> world cells (..., 2) (row, col) int64."""
        return np.floor(np.asarray(xy, float)[..., ::-1] / self.res).astype(np.int64)

    def cell_of(self, xy: np.ndarray) -> np.ndarray:
        """Map points (..., 2) [m] -> integer cells (..., 2) as (row, col) of the arrays now;
        points off the grid give indices outside [0, shape) (see :meth:`inside`)."""
        return self._world_cells(xy) - self.offset

    def centre_of(self, cells: np.ndarray) -> np.ndarray:
        """Cells (..., 2) (row, col) of the arrays now -> their centres (..., 2) (x, y) [m]."""
        return (np.asarray(cells)[..., ::-1] + self.offset[::-1] + 0.5) * self.res

    def inside(self, cells: np.ndarray) -> np.ndarray:
        return (cells[..., 0] >= 0) & (cells[..., 0] < self.shape[0]) & (cells[..., 1] >= 0) & (cells[..., 1] < self.shape[1])

    def cover(self, lower: np.ndarray, upper: np.ndarray) -> None:
        """Grow (by whole blocks) until the grid holds the points ``lower`` and ``upper`` (x, y)
        [m] and the rectangle between them; new cells are unknown."""
        self._cover_cells(self._world_cells(lower), self._world_cells(upper))

    def _cover_cells(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """Grow until the arrays hold world cells ``lo`` … ``hi`` (row, col), both included."""
        b = self.block_cells
        start = self.offset
        stop = self.offset + np.array(self.shape)
        if self.logodds.size == 0:
            new_start, new_stop = lo // b * b, -(-(hi + 1) // b) * b
        else:
            new_start = np.where(lo < start, lo // b * b, start)
            new_stop = np.where(hi >= stop, -(-(hi + 1) // b) * b, stop)
        if np.array_equal(new_start, start) and np.array_equal(new_stop, stop):
            return
        shape = tuple(int(n) for n in new_stop - new_start)
        (r0, c0), (h, w) = start - new_start, self.shape
        logodds, observed, contact = np.zeros(shape, np.float32), np.zeros(shape, bool), np.zeros(shape, bool)
        logodds[r0:r0 + h, c0:c0 + w] = self.logodds
        observed[r0:r0 + h, c0:c0 + w] = self.observed
        contact[r0:r0 + h, c0:c0 + w] = self.contact
        self.logodds, self.observed, self.contact, self.offset = logodds, observed, contact, new_start

    def probability(self) -> np.ndarray:
        """(H, W) occupancy probability; unobserved cells are exactly 0.5."""
        return 1.0 / (1.0 + np.exp(-self.logodds))

    def free(self) -> np.ndarray:
        return self.observed & (self.probability() < self.cfg.free_below)

    def occupied(self) -> np.ndarray:
        return self.observed & (self.probability() > self.cfg.occupied_above)

    def hit_logodds(self, ranges: np.ndarray) -> np.ndarray:
        """Log-odds a hit at each of ``ranges`` (N,) [m] adds to its end cell (N,): ``hit`` for
        exact ranges, less where the range error σ = ``range_noise``·range² spreads the surface
        over more than the cell (``GridConfig.range_noise``)."""
        c = self.cfg
        ranges = np.asarray(ranges, float)
        if c.range_noise <= 0:
            return np.full(ranges.shape, c.hit)
        sigma = np.maximum(c.range_noise * ranges**2, 1e-12)
        in_cell = special.erf(self.res / (2.0 * np.sqrt(2.0) * sigma))
        p = 0.5 + (special.expit(c.hit) - 0.5) * in_cell
        return special.logit(p)

    def insert(self, pose: np.ndarray, scan: Scan, teammates: np.ndarray | None = None) -> None:
        """Trace each beam from the robot at ``pose`` (x, y, θ) map frame: cells passed get
        ``miss``, the end cell of a hit :meth:`hit_logodds` of its range; hits on ``teammates`` (K, 2) [m], the other
        robots' positions, mark no obstacle (``teammate_radius``). The grid grows first to hold
        every cell marked (see the class).

        Vectorised over beams: points are sampled along every beam at half a cell apart. A pose
        or beams that are not finite mark nothing (they would stretch the grid without bound).
        """
        pose = np.asarray(pose, float)
        if not np.isfinite(pose).all():
            return
        ok = np.isfinite(scan.bearings) & np.isfinite(scan.ranges)
        if not ok.all():
            scan = Scan(scan.bearings[ok], scan.ranges[ok], scan.hit[ok])
        if teammates is not None:
            scan = scan.without_hits_near(pose, teammates, self.cfg.teammate_radius)
        ang = pose[2] + scan.bearings
        direction = np.column_stack([np.cos(ang), np.sin(ang)])  # (N, 2)
        steps = np.arange(0.0, float(scan.ranges.max(initial=0.0)), self.res / 2)
        beam, step = np.nonzero(steps[None, :] < scan.ranges[:, None] - self.res / 2)
        free = self._world_cells(pose[:2] + steps[step, None] * direction[beam])
        hits = self._world_cells(pose[:2] + scan.ranges[scan.hit, None] * direction[scan.hit])
        if not len(free) and not len(hits):
            return
        # the cells a beam passed with their 8 neighbours (a frontier needs its unknown neighbour
        # on the grid), the hit cells themselves (occupied: never a frontier)
        reach = np.concatenate([free - 1, free + 1, hits])
        self._cover_cells(reach.min(axis=0), reach.max(axis=0))
        width = self.shape[1]
        free_keys = np.unique((free[:, 0] - self.offset[0]) * width + free[:, 1] - self.offset[1])
        hit_keys, beam_of = np.unique((hits[:, 0] - self.offset[0]) * width + hits[:, 1] - self.offset[1],
                                      return_inverse=True)
        # a cell holding an obstacle end is not cleared by other beams, nor one a bumper touched
        cleared = np.setdiff1d(free_keys, hit_keys, assume_unique=True)
        cleared = cleared[~self.contact.ravel()[cleared]]
        c = self.cfg
        add = np.full(len(hit_keys), -np.inf)  # several beams ending in one cell: the surest counts
        np.maximum.at(add, beam_of.ravel(), self.hit_logodds(scan.ranges[scan.hit]))
        for keys, step in ((cleared, c.miss), (hit_keys, add)):
            rc = np.divmod(keys, width)
            self.logodds[rc] = np.clip(self.logodds[rc] + step, -c.clamp, c.clamp)
        self.observed[np.divmod(free_keys, width)] = True
        self.observed[np.divmod(hit_keys, width)] = True

    def touch(self, pose: np.ndarray, points: np.ndarray, teammates: np.ndarray | None = None) -> int:
        """Mark where a robot at ``pose`` (x, y, θ) map frame touched something: ``points`` (K, 2)
        (x, y) in its base_link [m] (its bumper, ``Simulation.contacts``). A touch is certain
        where a stereo scan is not: a wall without texture gives the camera no disparity, and one
        nearer than its near limit none at all, so a robot can press against an obstacle its
        scans never showed. The cells become occupied (log-odds ``clamp``) and beams never clear
        them. Points within ``teammate_radius`` of ``teammates`` (K, 2) [m] touched another robot
        and mark nothing. Returns the number of cells newly marked."""
        pose = np.asarray(pose, float)
        points = np.asarray(points, float).reshape(-1, 2)
        if not len(points) or not np.isfinite(pose).all():
            return 0
        c, s = np.cos(pose[2]), np.sin(pose[2])
        xy = pose[:2] + points @ np.array([[c, s], [-s, c]])
        xy = xy[np.isfinite(xy).all(axis=1)]
        if teammates is not None and len(xy) and self.cfg.teammate_radius > 0:
            mates = np.asarray(teammates, float).reshape(-1, 2)
            if len(mates):
                xy = xy[np.linalg.norm(xy[:, None] - mates[None], axis=2).min(axis=1) >= self.cfg.teammate_radius]
        if not len(xy):
            return 0
        cells = np.unique(self._world_cells(xy), axis=0)
        self._cover_cells(cells.min(axis=0), cells.max(axis=0))
        rc = tuple((cells - self.offset).T)
        new = int(np.count_nonzero(~self.contact[rc]))
        self.contact[rc] = True
        self.observed[rc] = True
        self.logodds[rc] = self.cfg.clamp
        return new


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
