"""Loading the filter's compiled kernels before the first real update.

numba loads a compiled kernel from its cache (or compiles it, once per machine) on the kernel's
first call in a process: 0.1–0.4 s for all of them with a warm cache, seconds with a cold one. A
node that pays this inside its first update holds the interpreter while its input queues fill;
:func:`warm_up` pays it at start-up instead, on a throwaway filter of the same kind.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from mrslam_core.slam.config import FilterConfig
from mrslam_core.slam.filter import MultiRobotFastSLAM, RobotUpdate
from mrslam_core.types import ObservationSet


def warm_up(cfg: FilterConfig, steps: int = 4, landmarks: int = 12) -> float:
    """Step a throwaway filter of ``cfg``'s model, proposal and association (at most 16
    particles) ``steps`` times on ``landmarks`` synthetic landmarks seen from a standing robot, so
    every kernel a step calls (gate, update, proposal, new landmarks, writes, resampling) is
    loaded now. Returns the wall time it took [s]."""
    t0 = time.perf_counter()
    rng = np.random.default_rng(0)
    slam = MultiRobotFastSLAM(replace(cfg, num_particles=min(cfg.num_particles, 16), seed=0), ["warm_up"],
                              np.zeros((1, 3)))
    points = np.column_stack([rng.uniform(2.0, 5.0, landmarks), rng.uniform(-1.5, 1.5, landmarks),
                              rng.uniform(0.2, 1.5, landmarks)])
    if cfg.observation_model == "range_bearing":
        z = np.column_stack([np.hypot(points[:, 0], points[:, 1]), np.arctan2(points[:, 1], points[:, 0])])
        cov = np.broadcast_to(np.diag([0.01, 1e-4]), (landmarks, 2, 2))
    else:
        z = points
        cov = np.broadcast_to(0.01 * np.eye(3), (landmarks, 3, 3))
    desc = rng.standard_normal((landmarks, 32)).astype(np.float32)
    desc /= np.linalg.norm(desc, axis=1, keepdims=True)
    tracks = np.arange(landmarks, dtype=np.int64)
    for k in range(1, steps + 1):
        stamp = int(k * 2e8)
        obs = ObservationSet("warm_up", stamp, z, cov, desc, tracks)
        slam.step([RobotUpdate("warm_up", stamp, np.zeros(3), obs)])
    # what the steps above need not reach: resampling's row copies, the held-slot union, the
    # pool rows of arbitrary (particle, slot) pairs
    slam.log_w = np.where(np.arange(slam.num_particles) == 0, 0.0, -50.0)  # one particle's copies
    slam._resample()
    slam.landmarks.held()
    slam.landmarks.rows(np.zeros(1, np.int64), np.zeros(1, np.int64))
    slam.best_map()
    return time.perf_counter() - t0
