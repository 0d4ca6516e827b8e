"""Worlds described in YAML: walls (segments), furniture (boxes), textures, start poses.

Map frame: x, y on the floor [m], z up; the world spans [0, size_x] × [0, size_y].

A world file::

    name: office
    size: [20.0, 12.0]          # [m]
    wall_height: 2.5            # defaults for walls that do not set their own [m]
    wall_thickness: 0.15
    walls:                      # a row [x1, y1, x2, y2] or a mapping
      - [0.0, 0.0, 20.0, 0.0]
      - {from: [0, 5], to: [3, 5], thickness: 0.1, height: 1.2, texture: repetitive}
    boxes:                      # furniture: a row [x, y, size_x, size_y, size_z, yaw_deg] or a mapping
      - [2.0, 1.0, 1.6, 0.8, 0.75, 0.0]
      - {centre: [5, 3], size: [0.6, 1.2, 1.8], yaw_deg: 0, texture: plain}
    repetitive: [5, 9]          # optional: wall indices given the repetitive texture
    start_poses: [[1.0, 6.0, 0.0]]   # x, y, θ [m, m, rad]

Textures: ``unique`` (procedural, seeded, rich in corners; the default), ``repetitive`` (one
pattern of look-alike corners repeated) or ``plain`` (uniform, featureless).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from scipy import ndimage

from mrslam_core.sim.errors import SimError

BUILTIN = Path(__file__).resolve().parent / "worlds"
TEXTURES = ("unique", "repetitive", "plain")


@dataclass(frozen=True)
class Solid:
    """A box standing on the floor.

    Attributes:
        centre: (2,) x, y of its centre in the map [m].
        half: (2,) half extents along its own x and y [m].
        yaw: rotation about z [rad].
        height: [m].
        texture: ``unique``, ``repetitive`` or ``plain``.
        index: position in the world's solid list (walls first, then boxes).
    """

    centre: np.ndarray
    half: np.ndarray
    yaw: float
    height: float
    texture: str
    index: int


@dataclass(frozen=True)
class World:
    """A parsed world.

    Attributes:
        name: world name.
        size: (size_x, size_y) [m].
        wall_height, wall_thickness: defaults of walls that do not set their own [m].
        walls: (W, 4) segments x1 y1 x2 y2 [m].
        boxes: (F, 6) furniture x y size_x size_y size_z yaw [m, m, m, m, m, rad].
        repetitive: indices of walls with the repetitive texture.
        start_poses: (S, 3) x y θ [m, m, rad].
        wall_heights, wall_thicknesses: (W,) per wall [m]; default the world's values.
        wall_textures: W texture names; default ``unique`` (``repetitive`` for those listed).
        box_textures: F texture names; default ``unique``.
    """

    name: str
    size: tuple[float, float]
    wall_height: float
    wall_thickness: float
    walls: np.ndarray
    boxes: np.ndarray
    repetitive: tuple[int, ...]
    start_poses: np.ndarray
    wall_heights: np.ndarray | None = None
    wall_thicknesses: np.ndarray | None = None
    wall_textures: tuple[str, ...] | None = None
    box_textures: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        n = len(self.walls)
        if self.wall_heights is None:
            object.__setattr__(self, "wall_heights", np.full(n, float(self.wall_height)))
        if self.wall_thicknesses is None:
            object.__setattr__(self, "wall_thicknesses", np.full(n, float(self.wall_thickness)))
        if self.wall_textures is None:
            tex = tuple("repetitive" if i in self.repetitive else "unique" for i in range(n))
            object.__setattr__(self, "wall_textures", tex)
        if self.box_textures is None:
            object.__setattr__(self, "box_textures", ("unique",) * len(self.boxes))

    def solids(self) -> list[Solid]:
        """Every wall (thickened segment, capped by half the thickness at both ends) and box."""
        out = []
        for k, ((x1, y1, x2, y2), h, t, tex) in enumerate(
                zip(self.walls, self.wall_heights, self.wall_thicknesses, self.wall_textures)):
            length = float(np.hypot(x2 - x1, y2 - y1))
            out.append(Solid(np.array([(x1 + x2) / 2, (y1 + y2) / 2]), np.array([length / 2 + t / 2, t / 2]),
                             float(np.arctan2(y2 - y1, x2 - x1)), float(h), tex, k))
        for k, ((x, y, sx, sy, sz, yaw), tex) in enumerate(zip(self.boxes, self.box_textures)):
            out.append(Solid(np.array([x, y]), np.array([sx / 2, sy / 2]), float(yaw), float(sz), tex,
                             len(self.walls) + k))
        return out

    def obstacles(self) -> list[tuple[np.ndarray, np.ndarray, float, float]]:
        """Every solid as (centre xy (2,), half extents xy (2,), yaw [rad], height [m])."""
        return [(s.centre, s.half, s.yaw, s.height) for s in self.solids()]

    def pieces(self, max_length: float = 1.5) -> list[Solid]:
        """Solids cut along their x axis into pieces no longer than ``max_length`` [m], so each
        piece carries its own texture at a sensible size (``index`` still names the solid)."""
        out = []
        for s in self.solids():
            n = max(1, int(np.ceil(2 * s.half[0] / max_length)))
            axis = np.array([np.cos(s.yaw), np.sin(s.yaw)])
            for k in range(n):
                offset = -s.half[0] + (2 * k + 1) * s.half[0] / n
                out.append(Solid(s.centre + offset * axis, np.array([s.half[0] / n, s.half[1]]), s.yaw,
                                 s.height, s.texture, s.index))
        return out

    def grid_shape(self, resolution: float) -> tuple[int, int]:
        """(rows, cols) of a raster of the world at ``resolution`` [m]."""
        return int(np.ceil(self.size[1] / resolution)), int(np.ceil(self.size[0] / resolution))

    def occupancy(self, resolution: float, inflate: float = 0.0) -> np.ndarray:
        """Ground-truth occupancy raster (H, W) bool, True = occupied.

        Cell (i, j) covers x ∈ [j·res, (j+1)·res), y ∈ [i·res, (i+1)·res) (origin at the map
        origin, rows along y); a cell is occupied when its centre is inside a solid grown by
        ``inflate`` [m] (a square grow, conservative at corners).
        """
        if resolution <= 0 or inflate < 0:
            raise SimError("occupancy: need resolution > 0 and inflate >= 0")
        h, w = self.grid_shape(resolution)
        gx, gy = np.meshgrid((np.arange(w) + 0.5) * resolution, (np.arange(h) + 0.5) * resolution)
        occ = np.zeros((h, w), bool)
        for s in self.solids():
            c, sn = np.cos(s.yaw), np.sin(s.yaw)
            dx, dy = gx - s.centre[0], gy - s.centre[1]
            occ |= (np.abs(c * dx + sn * dy) <= s.half[0] + inflate) & (np.abs(-sn * dx + c * dy) <= s.half[1] + inflate)
        return occ

    def reachable_free(self, resolution: float, robot_radius: float = 0.25,
                       starts: np.ndarray | None = None) -> np.ndarray:
        """Free cells a robot can reach: (H, W) bool, same raster as :meth:`occupancy`.

        The free space is what is left when the solids are grown by ``robot_radius`` [m] (where
        the robot's centre can go), taken over the 4-connected components that hold a start pose
        (default: all of the world's), and grown back by ``robot_radius`` within the true free
        space, so the cells the robot's body can sweep count as well. This is the denominator of
        an "explored fraction of the reachable free area".
        """
        occ = self.occupancy(resolution)
        centre_free = ~self.occupancy(resolution, inflate=robot_radius)
        labels, _ = ndimage.label(centre_free)
        starts = self.start_poses if starts is None else np.asarray(starts, float).reshape(-1, 3)
        h, w = occ.shape
        ij = np.floor(starts[:, [1, 0]] / resolution).astype(int)
        inside = (ij[:, 0] >= 0) & (ij[:, 0] < h) & (ij[:, 1] >= 0) & (ij[:, 1] < w)
        keep = np.unique(labels[ij[inside, 0], ij[inside, 1]])
        reach = np.isin(labels, keep[keep > 0])
        grow = robot_radius + resolution  # one cell more: cell centres sit up to a cell from the solids
        r = int(np.ceil(grow / resolution))
        yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
        disk = (yy ** 2 + xx ** 2) * resolution ** 2 <= grow ** 2
        return ndimage.binary_dilation(reach, structure=disk) & ~occ


def _rows(path: Path, key: str, rows: Any, cols: int) -> np.ndarray:
    try:
        arr = np.asarray(rows, dtype=float).reshape(-1, cols)
    except (TypeError, ValueError) as exc:
        raise SimError(f"{path}: {key} must be a list of {cols}-number rows") from exc
    if not np.isfinite(arr).all():
        raise SimError(f"{path}: {key} has non-finite values")
    return arr


def _numbers(path: Path, key: str, value: Any, n: int) -> list[float]:
    try:
        out = [float(v) for v in value]
    except (TypeError, ValueError) as exc:
        raise SimError(f"{path}: {key} must be {n} numbers") from exc
    if len(out) != n or not np.isfinite(out).all():
        raise SimError(f"{path}: {key} must be {n} finite numbers")
    return out


def _texture(path: Path, key: str, value: Any) -> str:
    if value not in TEXTURES:
        raise SimError(f"{path}: {key}: texture must be one of {list(TEXTURES)}, got {value!r}")
    return str(value)


def _parse_walls(path: Path, entries: Any, height: float, thickness: float):
    if not isinstance(entries, list) or not entries:
        raise SimError(f"{path}: walls must be a non-empty list")
    segs, hs, ts, texs = [], [], [], []
    for i, e in enumerate(entries):
        key = f"walls[{i}]"
        if isinstance(e, dict):
            extra = sorted(set(e) - {"from", "to", "height", "thickness", "texture"})
            if extra or "from" not in e or "to" not in e:
                raise SimError(f"{path}: {key} needs from, to and optional height, thickness, texture"
                               + (f" (unknown key {extra[0]})" if extra else ""))
            segs.append(_numbers(path, f"{key}.from", e["from"], 2) + _numbers(path, f"{key}.to", e["to"], 2))
            hs.append(float(e.get("height", height)))
            ts.append(float(e.get("thickness", thickness)))
            texs.append(_texture(path, key, e.get("texture", "unique")))
        else:
            try:
                segs.append(_numbers(path, key, e, 4))
            except SimError as exc:
                raise SimError(f"{path}: walls must be a list of 4-number rows or mappings ({key})") from exc
            hs.append(height)
            ts.append(thickness)
            texs.append("unique")
        if hs[-1] <= 0 or ts[-1] <= 0:
            raise SimError(f"{path}: {key}: height and thickness must be > 0")
        if np.hypot(segs[-1][2] - segs[-1][0], segs[-1][3] - segs[-1][1]) <= 0:
            raise SimError(f"{path}: {key} has zero length")
    return np.array(segs), np.array(hs), np.array(ts), texs


def _parse_boxes(path: Path, entries: Any):
    if entries is None:
        entries = []
    if not isinstance(entries, list):
        raise SimError(f"{path}: boxes must be a list")
    rows, texs = [], []
    for i, e in enumerate(entries):
        key = f"boxes[{i}]"
        if isinstance(e, dict):
            extra = sorted(set(e) - {"centre", "size", "yaw_deg", "texture"})
            if extra or "centre" not in e or "size" not in e:
                raise SimError(f"{path}: {key} needs centre, size and optional yaw_deg, texture"
                               + (f" (unknown key {extra[0]})" if extra else ""))
            rows.append(_numbers(path, f"{key}.centre", e["centre"], 2) + _numbers(path, f"{key}.size", e["size"], 3)
                        + [float(e.get("yaw_deg", 0.0))])
            texs.append(_texture(path, key, e.get("texture", "unique")))
        else:
            try:
                rows.append(_numbers(path, key, e, 6))
            except SimError as exc:
                raise SimError(f"{path}: boxes must be a list of 6-number rows or mappings ({key})") from exc
            texs.append("unique")
        if min(rows[-1][2:5]) <= 0:
            raise SimError(f"{path}: {key}: sizes must be > 0")
    arr = np.array(rows, float).reshape(-1, 6)
    arr[:, 5] = np.radians(arr[:, 5])
    return arr, texs


def load_world(name_or_path: str | Path) -> World:
    """A built-in world by name (``office``, ``small``, ``hall40x30``) or a world YAML file.

    Raises:
        SimError: unknown name, unreadable file, or a malformed field (named in the message).
    """
    path = Path(name_or_path)
    if not path.suffix:
        path = BUILTIN / f"{name_or_path}.yaml"
    if not path.is_file():
        have = sorted(q.stem for q in BUILTIN.glob("*.yaml"))
        raise SimError(f"no world {str(name_or_path)!r} (built-in worlds: {have}, or give a YAML path)")
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise SimError(f"{path}: cannot read it as YAML: {exc}") from exc
    if not isinstance(data, dict):
        raise SimError(f"{path}: the top level must be a mapping")
    known = {"name", "size", "wall_height", "wall_thickness", "walls", "boxes", "repetitive", "start_poses"}
    unknown = sorted(set(data) - known)
    if unknown:
        raise SimError(f"{path}: unknown key {unknown[0]} (known: {sorted(known)})")
    for key in ("size", "walls", "start_poses"):
        if key not in data:
            raise SimError(f"{path}: missing key {key}")
    size = _numbers(path, "size", data["size"], 2)
    if min(size) <= 0:
        raise SimError(f"{path}: size must be [size_x, size_y] > 0")
    height = float(data.get("wall_height", 2.5))
    thickness = float(data.get("wall_thickness", 0.15))
    walls, heights, thicknesses, wall_tex = _parse_walls(path, data["walls"], height, thickness)
    boxes, box_tex = _parse_boxes(path, data.get("boxes"))
    try:
        repetitive = tuple(int(i) for i in data.get("repetitive") or [])
    except (TypeError, ValueError) as exc:
        raise SimError(f"{path}: repetitive must be a list of wall indices") from exc
    if any(not 0 <= i < len(walls) for i in repetitive):
        raise SimError(f"{path}: repetitive names a wall index outside 0..{len(walls) - 1}")
    for i in repetitive:
        wall_tex[i] = "repetitive"
    repetitive = tuple(i for i, t in enumerate(wall_tex) if t == "repetitive")
    starts = _rows(path, "start_poses", data["start_poses"], 3)
    if not len(starts):
        raise SimError(f"{path}: start_poses is empty")
    outside = (starts[:, 0] < 0) | (starts[:, 0] > size[0]) | (starts[:, 1] < 0) | (starts[:, 1] > size[1])
    if outside.any():
        raise SimError(f"{path}: start pose {int(np.argmax(outside))} lies outside the world")
    return World(name=str(data.get("name", path.stem)), size=(size[0], size[1]), wall_height=height,
                 wall_thickness=thickness, walls=walls, boxes=boxes, repetitive=repetitive, start_poses=starts,
                 wall_heights=heights, wall_thicknesses=thicknesses, wall_textures=tuple(wall_tex),
                 box_textures=tuple(box_tex))
