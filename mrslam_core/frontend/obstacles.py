"""2D obstacles and free space for the occupancy grid, from stereo depth, as a pseudo laser scan."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from mrslam_core.frontend.camera import StereoRig
from mrslam_core.frontend.config import FrontendConfig


@dataclass(frozen=True)
class ObstacleScan:
    """A pseudo laser scan in base_link (x forward, y left), like sensor_msgs/LaserScan.

    Bin i covers bearings [angle_min + i·angle_increment, angle_min + (i+1)·angle_increment).

    Attributes:
        stamp_ns: image time (ns).
        angle_min: bearing of the first bin's lower edge [rad] (counter-clockwise from x).
        angle_increment: bin width [rad].
        ranges: (n,) distance in the xy plane to the nearest point in the obstacle height band
            [m]; inf where the bin saw no obstacle within range_max.
        free_ranges: (n,) the bin's ray is known free up to this distance [m] (floor seen up to
            there, cut at the nearest obstacle); 0 where nothing is known.
        range_max: [m].
        points: (M, 2) obstacle points (x, y) in base_link [m] (within range_max and the bins).
    """

    stamp_ns: int
    angle_min: float
    angle_increment: float
    ranges: np.ndarray
    free_ranges: np.ndarray
    range_max: float
    points: np.ndarray

    @property
    def angle_max(self) -> float:
        """Upper edge of the last bin [rad]."""
        return self.angle_min + self.angle_increment * self.ranges.size


def scan_from_points(
    points: np.ndarray, stamp_ns: int, angle_min: float, angle_max: float, cfg: FrontendConfig
) -> ObstacleScan:
    """Bin base_link points (P, 3) [m] into an :class:`ObstacleScan`.

    Points with z in [obstacle_min_height, obstacle_max_height] are obstacles; points below the
    band are floor and mark their bearing free up to their distance.
    """
    n = cfg.scan_bins
    inc = (angle_max - angle_min) / n
    rng = np.hypot(points[:, 0], points[:, 1])
    b = np.floor((np.arctan2(points[:, 1], points[:, 0]) - angle_min) / inc).astype(np.int64)
    inside = (b >= 0) & (b < n) & (rng <= cfg.scan_max_range) & np.isfinite(rng)
    z = points[:, 2]
    obst = inside & (z >= cfg.obstacle_min_height) & (z <= cfg.obstacle_max_height)
    floor = inside & (z < cfg.obstacle_min_height)
    ranges = np.full(n, np.inf)
    np.minimum.at(ranges, b[obst], rng[obst])
    free = np.zeros(n)
    np.maximum.at(free, b[floor], rng[floor])
    free = np.minimum(free, ranges)
    return ObstacleScan(int(stamp_ns), float(angle_min), float(inc), ranges, free,
                        float(cfg.scan_max_range), points[obst, :2].copy())


class ObstacleScanner:
    """Pseudo scans from dense block-matching disparity (reduced image) or from feature points.

    Args:
        rig: the stereo rig (rectified intrinsics, base_link <- rectified left camera).
        cfg: obstacle band, scan bins and range, dense settings.
    """

    def __init__(self, rig: StereoRig, cfg: FrontendConfig):
        self.rig = rig
        self.cfg = cfg
        rot = rig.t_base_rect[:3, :3]
        edge = np.array([[(0.0 - rig.cx) / rig.f, 0.0, 1.0], [(rig.width - 1 - rig.cx) / rig.f, 0.0, 1.0]])
        ray = edge @ rot.T
        bearings = np.arctan2(ray[:, 1], ray[:, 0])
        self.angle_min = float(bearings.min())
        self.angle_max = float(bearings.max())
        ds = cfg.dense_downsample
        self._ds = ds
        hs, ws = rig.height // ds, rig.width // ds
        num = 16 * int(np.ceil(max(cfg.max_disparity / ds, 16) / 16))
        self._bm = cv2.StereoBM_create(numDisparities=num, blockSize=9)
        self._bm.setMinDisparity(int(cfg.min_disparity // ds))
        self._bm.setUniquenessRatio(15)
        self._bm.setTextureThreshold(10)
        self._bm.setSpeckleWindowSize(50)
        self._bm.setSpeckleRange(2)
        # pixel centres of the reduced image in full-resolution coordinates
        cols = (np.arange(ws) + 0.5) * ds - 0.5
        rows = (np.arange(hs) + 0.5) * ds - 0.5
        self._u = ((cols - rig.cx) / rig.f)[None, :].repeat(hs, 0).ravel()
        self._v = ((rows - rig.cy) / rig.f)[:, None].repeat(ws, 1).ravel()
        self._size = (ws, hs)

    def from_points(self, points_base: np.ndarray, stamp_ns: int) -> ObstacleScan:
        """Scan from already triangulated base_link points (P, 3) [m]."""
        return scan_from_points(points_base, stamp_ns, self.angle_min, self.angle_max, self.cfg)

    def disparity(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """Block-matching disparity of a rectified grey pair (H, W) uint8 at the reduced resolution:
        (H // ds, W // ds) float32 in full-resolution pixels, ≤ 0 where none was found; reduced
        pixel (i, j) covers full-resolution rows i·ds … i·ds + ds − 1 and those columns."""
        if self._ds > 1:
            left = cv2.resize(left, self._size, interpolation=cv2.INTER_AREA)
            right = cv2.resize(right, self._size, interpolation=cv2.INTER_AREA)
        return self._bm.compute(left, right).astype(np.float32) * (self._ds / 16.0)

    def from_images(self, left: np.ndarray, right: np.ndarray, stamp_ns: int) -> ObstacleScan:
        """Scan from a rectified grey pair (H, W) uint8 by block matching at reduced resolution."""
        disp = self.disparity(left, right)
        with np.errstate(divide="ignore"):
            z = np.where(disp > 0, (self.rig.f * self.rig.baseline) / disp, np.inf)
        return self.from_depth(z, stamp_ns)

    def from_depth(self, z: np.ndarray, stamp_ns: int) -> ObstacleScan:
        """Scan from depth along the optical axis at the reduced pixels (H // ds, W // ds) [m]
        (:meth:`disparity`'s pixels); depths that are not finite or outside [min_depth,
        max_depth] are none."""
        z = np.asarray(z).ravel()
        keep = np.isfinite(z) & (z >= self.cfg.min_depth) & (z <= self.cfg.max_depth)
        z = z[keep]
        pts = np.stack([self._u[keep] * z, self._v[keep] * z, z], axis=1)
        t = self.rig.t_base_rect
        return self.from_points(pts @ t[:3, :3].T + t[:3, 3], stamp_ns)
