"""TUM trajectory files: one line per pose, ``t x y z qx qy qz qw`` (t in s), readable by evo."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mrslam_core.geometry.se2 import quaternion_to_yaw, yaw_to_quaternion


def write_tum(path: str | Path, t: np.ndarray, poses: np.ndarray, z: float = 0.0) -> None:
    """Write planar poses (N, 3) at times t (N,) [s] as a TUM file (z constant)."""
    t = np.asarray(t, float)
    poses = np.asarray(poses, float)
    q = yaw_to_quaternion(poses[:, 2])
    rows = np.column_stack([t, poses[:, 0], poses[:, 1], np.full(len(t), z), q])
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    np.savetxt(path, rows, fmt="%.9f %.6f %.6f %.6f %.9f %.9f %.9f %.9f")


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM file: (t (N,) [s], planar poses (N, 3)); z and roll/pitch are ignored."""
    data = np.loadtxt(path, comments="#", ndmin=2)
    if data.shape[1] != 8:
        raise ValueError(f"{path}: a TUM file has 8 columns, found {data.shape[1]}")
    return data[:, 0], np.column_stack([data[:, 1], data[:, 2], quaternion_to_yaw(data[:, 4:8])])
