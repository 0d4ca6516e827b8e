"""A synthetic stereo world: landmarks with descriptors, robots on closed loops, noisy sensors.

Used by the filter's tests and by ``mrslam bench filter``. Observations are generated with the
stereo noise model of 000 eq. 12 (pixel noise σd, σr, σc propagated to a 3D covariance), so the
covariance each observation carries is the one its noise was drawn from.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mrslam_core.geometry.se2 import between, compose, wrap_angle
from mrslam_core.geometry.stereo import project, triangulation_covariance
from mrslam_core.slam.config import MotionConfig
from mrslam_core.slam.filter import RobotUpdate
from mrslam_core.slam.motion import sample_motion
from mrslam_core.types import ObservationSet

# base_link (x fwd, y left, z up) <- optical (x right, y down, z fwd)
R_BASE_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


@dataclass(frozen=True)
class SyntheticWorldConfig:
    """Parameters of the synthetic world (sizes in m, angles in rad, pixels in px)."""

    num_landmarks: int = 400
    width: float = 20.0
    height: float = 12.0
    landmark_z: tuple[float, float] = (0.2, 2.5)
    descriptor_dim: int = 64
    descriptor_noise: float = 0.02
    num_robots: int = 3
    dt: float = 0.5
    speed: float = 0.4
    focal_px: float = 400.0
    image_size: tuple[int, int] = (640, 480)
    baseline: float = 0.12
    camera_height: float = 0.5
    max_range: float = 6.0
    min_range: float = 0.5
    sigma_d: float = 0.3
    sigma_r: float = 1.0
    sigma_c: float = 1.0
    max_observations: int = 20
    odometry_noise: MotionConfig = field(default_factory=MotionConfig)
    cluster_size: int = 1  # landmarks per cluster (ambiguous worlds: > 1)
    cluster_spread: float = 0.0  # m, σ of landmarks around their cluster centre
    descriptor_pool: int = 0  # distinct descriptors shared by all landmarks (0: all distinct)
    fov: float | None = None  # rad, horizontal field of view limit (None: the image's)
    seed: int = 0


class SyntheticWorld:
    """Landmarks (N, 3) in the map with unit descriptors (N, D), and K robots on loops."""

    def __init__(self, cfg: SyntheticWorldConfig):
        self.cfg = cfg
        rng = np.random.default_rng(cfg.seed)
        n = cfg.num_landmarks
        centres = np.column_stack(
            [
                rng.uniform(0, cfg.width, -(-n // cfg.cluster_size)),
                rng.uniform(0, cfg.height, -(-n // cfg.cluster_size)),
                rng.uniform(*cfg.landmark_z, -(-n // cfg.cluster_size)),
            ]
        )
        self.landmarks = np.repeat(centres, cfg.cluster_size, axis=0)[:n]
        self.landmarks += cfg.cluster_spread * rng.standard_normal((n, 3))
        pool = cfg.descriptor_pool or n
        d = rng.standard_normal((pool, cfg.descriptor_dim))
        d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
        self.descriptors = d[rng.integers(0, pool, n)] if cfg.descriptor_pool else d
        self.robots = [f"robot{i + 1}" for i in range(cfg.num_robots)]
        self.rng = np.random.default_rng(cfg.seed + 1)

    def start_poses(self) -> np.ndarray:
        """(K, 3) start poses: robots spread on a loop around the middle of the world."""
        return np.array([self.pose(k, 0.0) for k in range(self.cfg.num_robots)])

    def pose(self, k: int, t: float) -> np.ndarray:
        """Ground-truth pose (3,) of robot k at time t [s]: an ellipse, each robot offset in phase."""
        cfg = self.cfg
        ax, ay = 0.35 * cfg.width, 0.3 * cfg.height
        cx, cy = cfg.width / 2, cfg.height / 2
        perimeter = np.pi * (3 * (ax + ay) - np.sqrt((3 * ax + ay) * (ax + 3 * ay)))
        phase = 2 * np.pi * k / max(cfg.num_robots, 1) + 2 * np.pi * cfg.speed * t / perimeter
        x, y = cx + ax * np.cos(phase), cy + ay * np.sin(phase)
        heading = np.arctan2(ay * np.cos(phase), -ax * np.sin(phase))
        return np.array([x, y, wrap_angle(heading)])

    def observe(self, k: int, pose: np.ndarray, stamp_ns: int) -> ObservationSet:
        """Stereo observations of the landmarks in view of robot k at ``pose``."""
        cfg = self.cfg
        c, s = np.cos(pose[2]), np.sin(pose[2])
        d = self.landmarks[:, :2] - pose[:2]
        base = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1],
                                self.landmarks[:, 2] - cfg.camera_height])
        optical = base @ R_BASE_OPTICAL  # rows: R_BASE_OPTICAL.T @ p
        w, h = cfg.image_size
        rcd = project(optical, cfg.focal_px, w / 2, h / 2, cfg.baseline) if len(optical) else optical
        rng_xy = np.hypot(base[:, 0], base[:, 1])
        vis = (
            (optical[:, 2] > cfg.min_range)
            & (rng_xy < cfg.max_range)
            & (np.abs(np.arctan2(base[:, 1], base[:, 0])) <= (cfg.fov or 2 * np.pi) / 2)
            & (rcd[:, 1] >= 0) & (rcd[:, 1] < w) & (rcd[:, 0] >= 0) & (rcd[:, 0] < h)
        )
        idx = np.flatnonzero(vis)
        idx = idx[np.argsort(rng_xy[idx])][: cfg.max_observations]
        r, col, disp = rcd[idx, 0], rcd[idx, 1], rcd[idx, 2]
        cov_opt = triangulation_covariance(
            r, col, disp, cfg.focal_px, w / 2, h / 2, cfg.baseline, cfg.sigma_d, cfg.sigma_r, cfg.sigma_c
        )
        cov = R_BASE_OPTICAL @ cov_opt @ R_BASE_OPTICAL.T
        chol = np.linalg.cholesky(cov)
        z = base[idx] + (chol @ self.rng.standard_normal((idx.size, 3, 1)))[..., 0]
        z[:, 2] += cfg.camera_height
        desc = self.descriptors[idx] + cfg.descriptor_noise * self.rng.standard_normal(
            (idx.size, cfg.descriptor_dim)
        ).astype(np.float32)
        desc /= np.linalg.norm(desc, axis=1, keepdims=True)
        return ObservationSet(self.robots[k], stamp_ns, z, cov, desc, idx.astype(np.int64))

    def noisy_odometry(self, delta: np.ndarray) -> np.ndarray:
        """What odometry reports for a true relative motion (3,): the motion model's noise.

        Drawn as ⊖x ⊕ x' where x' is sampled from the odometry motion model around the true
        motion, so the filter's motion model with the same parameters is exactly right.
        """
        noisy = sample_motion(np.zeros((1, 3)), delta, self.cfg.odometry_noise, self.rng)[0]
        return noisy

    def run(self, steps: int):
        """Yield (t [s], true poses (K, 3), odometry poses (K, 3), [RobotUpdate per robot])."""
        cfg = self.cfg
        k_all = range(cfg.num_robots)
        prev = self.start_poses()
        odom = prev.copy()
        for i in range(1, steps + 1):
            t = i * cfg.dt
            stamp = int(round(t * 1e9))
            true = np.array([self.pose(k, t) for k in k_all])
            updates = []
            for k in k_all:
                delta = self.noisy_odometry(between(prev[k], true[k]))
                odom[k] = compose(odom[k], delta)
                updates.append(RobotUpdate(self.robots[k], stamp, delta, self.observe(k, true[k], stamp)))
            prev = true
            yield t, true, odom.copy(), updates
