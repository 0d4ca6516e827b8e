"""A fast 2D team simulation for exploration experiments: unicycle robots on a world's
ground-truth occupancy raster with a ray-marched range sensor (no rendering, no SLAM)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from mrslam_core.control.config import ControlConfig
from mrslam_core.control.controller import Controller
from mrslam_core.exploration.config import ExplorationConfig, GridConfig
from mrslam_core.exploration.explorer import Explorer, State
from mrslam_core.exploration.grid import OccupancyGrid, Scan
from mrslam_core.geometry.se2 import wrap_angle
from mrslam_core.sim.world import World


@dataclass(frozen=True)
class SensorConfig:
    """Range sensor: bearings over ±fov/2 [rad], max range [m], scans per second."""

    fov: float = np.radians(90.0)
    beams: int = 46
    max_range: float = 4.0
    rate_hz: float = 2.0


class TeamSim2D:
    """Robots on ``world``'s occupancy raster (resolution ``res``), exploring with ``explorer``
    (``explore``), driven by its controller (``control``)."""

    def __init__(self, world: World, robots: int, explore: ExplorationConfig, sensor: SensorConfig | None = None,
                 res: float = 0.05, grid: GridConfig | None = None, seed: int = 0,
                 control: ControlConfig | None = None):
        self.world = world
        self.res = res
        self.truth = world.occupancy(res)
        self.sensor = sensor or SensorConfig()
        rng = np.random.default_rng(seed)
        starts = np.array(world.start_poses[:robots], float)
        starts[:, 2] = wrap_angle(starts[:, 2] + rng.uniform(-0.3, 0.3, robots))
        self.names = [f"robot{i + 1}" for i in range(robots)]
        self.poses = {n: starts[i].copy() for i, n in enumerate(self.names)}
        self.grid = OccupancyGrid(grid or GridConfig())
        self.explorer = Explorer(explore, self.names, Controller(control))
        body = ndimage.distance_transform_edt(~self.truth) * res <= 0.2
        lab, _ = ndimage.label(~body)
        start_cell = np.floor(starts[0, 1::-1] / res).astype(int)
        self.reachable = lab == lab[tuple(start_cell)]
        self.time = 0.0

    def scan(self, pose: np.ndarray) -> Scan:
        s = self.sensor
        bearings = np.linspace(-s.fov / 2, s.fov / 2, s.beams)
        steps = np.arange(0, s.max_range, self.res / 2)
        ang = pose[2] + bearings
        pts = pose[:2] + steps[None, :, None] * np.stack([np.cos(ang), np.sin(ang)], -1)[:, None, :]
        ij = np.floor(pts[..., ::-1] / self.res).astype(int)
        inside = (ij[..., 0] >= 0) & (ij[..., 0] < self.truth.shape[0]) & (ij[..., 1] >= 0) & (ij[..., 1] < self.truth.shape[1])
        occ = np.ones(inside.shape, bool)
        occ[inside] = self.truth[ij[..., 0][inside], ij[..., 1][inside]]
        first = np.where(occ.any(axis=1), occ.argmax(axis=1), len(steps))
        hit = first < len(steps)
        ranges = np.where(hit, steps[np.minimum(first, len(steps) - 1)], s.max_range)
        return Scan(bearings, ranges, hit)

    def _free(self, xy: np.ndarray) -> bool:
        i, j = np.floor(xy[::-1] / self.res).astype(int)
        return bool(0 <= i < self.truth.shape[0] and 0 <= j < self.truth.shape[1] and self.reachable[i, j])

    def explored_fraction(self) -> float:
        seen = self.grid.observed
        # grid cells -> truth raster cells
        h, w = self.reachable.shape
        yy, xx = np.mgrid[0:h, 0:w]
        centres = (np.stack([xx, yy], -1) + 0.5) * self.res
        cells = self.grid.cell_of(centres)
        ok = self.grid.inside(cells)
        known = np.zeros((h, w), bool)
        known[ok] = seen[cells[..., 0][ok], cells[..., 1][ok]]
        return float((known & self.reachable).sum() / self.reachable.sum())

    def run(self, seconds: float, dt: float = 0.1, stop_at: float = 0.999) -> list[tuple[float, float]]:
        """Simulate; returns [(time [s], explored fraction)] once per second."""
        curve = []
        next_scan = 0.0
        next_log = 0.0
        while self.time < seconds:
            if self.time >= next_scan:
                for n in self.names:
                    self.grid.insert(self.poses[n], self.scan(self.poses[n]))
                next_scan += 1.0 / self.sensor.rate_hz
            if self.time >= next_log:
                curve.append((self.time, self.explored_fraction()))
                next_log += 1.0
                if curve[-1][1] >= stop_at:
                    break
            commands = self.explorer.step(self.grid, self.poses, self.time)
            if self.explorer.state is State.COMPLETE:
                curve.append((self.time, self.explored_fraction()))
                break
            for n, (v, w) in commands.items():
                p = self.poses[n]
                nxt = p + dt * np.array([v * np.cos(p[2]), v * np.sin(p[2]), w])
                for cand in (nxt[:2], np.array([nxt[0], p[1]]), np.array([p[0], nxt[1]])):  # slide along walls
                    if self._free(cand):
                        p[:2] = cand
                        break
                p[2] = wrap_angle(nxt[2])
            self.time += dt
        return curve
