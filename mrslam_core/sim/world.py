"""Worlds described in YAML: walls (segments), furniture (boxes), textures, start poses.

Map frame: x, y on the floor [m], z up; the world spans [0, size_x] × [0, size_y].
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from mrslam_core.sim.errors import SimError

BUILTIN = Path(__file__).resolve().parent / "worlds"


@dataclass(frozen=True)
class World:
    """A parsed world.

    Attributes:
        name: world name.
        size: (size_x, size_y) [m].
        wall_height, wall_thickness: [m].
        walls: (W, 4) segments x1 y1 x2 y2 [m].
        boxes: (F, 6) furniture x y size_x size_y size_z yaw [m, m, m, m, m, rad].
        repetitive: indices of walls with a repeated texture.
        start_poses: (S, 3) x y θ [m, m, rad].
    """

    name: str
    size: tuple[float, float]
    wall_height: float
    wall_thickness: float
    walls: np.ndarray
    boxes: np.ndarray
    repetitive: tuple[int, ...]
    start_poses: np.ndarray

    def obstacles(self) -> list[tuple[np.ndarray, np.ndarray, float, float]]:
        """Every solid as (centre xy (2,), half extents xy (2,), yaw [rad], height [m])."""
        out = []
        for x1, y1, x2, y2 in self.walls:
            length = float(np.hypot(x2 - x1, y2 - y1))
            out.append((np.array([(x1 + x2) / 2, (y1 + y2) / 2]),
                        np.array([length / 2 + self.wall_thickness / 2, self.wall_thickness / 2]),
                        float(np.arctan2(y2 - y1, x2 - x1)), self.wall_height))
        for x, y, sx, sy, sz, yaw in self.boxes:
            out.append((np.array([x, y]), np.array([sx / 2, sy / 2]), float(yaw), float(sz)))
        return out

    def visual_pieces(self, max_length: float = 1.5) -> list[tuple[np.ndarray, np.ndarray, float, float, int]]:
        """Solids cut into pieces no longer than ``max_length`` [m], so each piece carries its
        own texture at a sensible scale: (centre xy, half extents xy, yaw, height, solid index)."""
        out = []
        for idx, (centre, half, yaw, height) in enumerate(self.obstacles()):
            n = max(1, int(np.ceil(2 * half[0] / max_length)))
            c, s = np.cos(yaw), np.sin(yaw)
            for k in range(n):
                offset = -half[0] + (2 * k + 1) * half[0] / n
                out.append((centre + offset * np.array([c, s]), np.array([half[0] / n, half[1]]), yaw, height, idx))
        return out

    def occupancy(self, resolution: float, inflate: float = 0.0) -> np.ndarray:
        """Ground-truth occupancy raster (H, W) bool, True = occupied; cell (i, j) covers
        x ∈ [j·res, (j+1)·res), y ∈ [i·res, (i+1)·res). ``inflate`` grows solids [m]."""
        w = int(np.ceil(self.size[0] / resolution))
        h = int(np.ceil(self.size[1] / resolution))
        xs = (np.arange(w) + 0.5) * resolution
        ys = (np.arange(h) + 0.5) * resolution
        gx, gy = np.meshgrid(xs, ys)
        occ = np.zeros((h, w), bool)
        for centre, half, yaw, _ in self.obstacles():
            c, s = np.cos(yaw), np.sin(yaw)
            dx, dy = gx - centre[0], gy - centre[1]
            u, v = c * dx + s * dy, -s * dx + c * dy
            occ |= (np.abs(u) <= half[0] + inflate) & (np.abs(v) <= half[1] + inflate)
        return occ


def load_world(name_or_path: str | Path) -> World:
    """A built-in world by name (``office``, ``small``) or a world YAML file.

    Raises:
        SimError: unknown name, unreadable file, or a malformed field (named in the message).
    """
    path = Path(name_or_path)
    if not path.suffix:
        path = BUILTIN / f"{name_or_path}.yaml"
    if not path.is_file():
        have = sorted(p.stem for p in BUILTIN.glob("*.yaml"))
        raise SimError(f"no world {name_or_path!r} (built-in worlds: {have}, or give a YAML path)")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise SimError(f"{path}: not valid YAML: {exc}") from exc
    if not isinstance(data, dict):
        raise SimError(f"{path}: the top level must be a mapping")
    known = {"name", "size", "wall_height", "wall_thickness", "walls", "boxes", "repetitive", "start_poses"}
    unknown = sorted(set(data) - known)
    if unknown:
        raise SimError(f"{path}: unknown key {unknown[0]} (known: {sorted(known)})")

    def table(key: str, cols: int, required: bool = True) -> np.ndarray:
        rows = data.get(key, [] if not required else None)
        if rows is None:
            raise SimError(f"{path}: missing key {key}")
        try:
            arr = np.asarray(rows, dtype=float).reshape(-1, cols)
        except (TypeError, ValueError) as exc:
            raise SimError(f"{path}: {key} must be a list of {cols}-number rows") from exc
        if not np.isfinite(arr).all():
            raise SimError(f"{path}: {key} has non-finite values")
        return arr

    try:
        size = tuple(float(v) for v in data["size"])
        if len(size) != 2 or min(size) <= 0:
            raise ValueError
    except (KeyError, TypeError, ValueError) as exc:
        raise SimError(f"{path}: size must be [size_x, size_y] > 0") from exc
    boxes = table("boxes", 6, required=False)
    boxes[:, 5] = np.radians(boxes[:, 5])
    walls = table("walls", 4)
    repetitive = tuple(int(i) for i in data.get("repetitive", []))
    if any(not 0 <= i < len(walls) for i in repetitive):
        raise SimError(f"{path}: repetitive names a wall index outside 0..{len(walls) - 1}")
    return World(
        name=str(data.get("name", path.stem)),
        size=size,  # type: ignore[arg-type]
        wall_height=float(data.get("wall_height", 2.5)),
        wall_thickness=float(data.get("wall_thickness", 0.15)),
        walls=walls,
        boxes=boxes,
        repetitive=repetitive,
        start_poses=table("start_poses", 3),
    )
