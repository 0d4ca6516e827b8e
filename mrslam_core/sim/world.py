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

Every world is checked when loaded (:func:`check_world`): walls must not overlap (run along each
other or cross; they may meet at their ends or in a T), and every start pose must be clear of the
walls and boxes by the robot's half width and reachable from the first one. Each error names the
field, e.g. ``walls[5] crosses walls[2]`` or ``start_poses[1] ... cannot be reached``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from scipy import ndimage

from mrslam_core.control.platform import PlatformConfig
from mrslam_core.sim.errors import SimError

BUILTIN = Path(__file__).resolve().parent / "worlds"
TEXTURES = ("unique", "repetitive", "plain")
#: half the width of the simulated robot's body (its footprint: ``PlatformConfig``'s defaults,
#: which the simulator builds the body from): a start pose nearer than this to a solid puts the
#: robot inside it [m]
ROBOT_HALF_WIDTH = PlatformConfig().width / 2
#: the clearance [m] of "reachable": a robot's centre keeps this far from every solid (passages
#: narrower than twice this do not connect), in reachable_free and the start-pose check
REACH_RADIUS = 0.25
#: the raster [m] on which start poses are checked for reachability
CHECK_RESOLUTION = 0.1
#: walls that run along each other for more than this overlap [m]
OVERLAP_TOLERANCE = 0.01


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
        out = [wall_solid(seg, t, h, tex, k) for k, (seg, h, t, tex) in
               enumerate(zip(self.walls, self.wall_heights, self.wall_thicknesses, self.wall_textures))]
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
        occ = np.zeros(self.grid_shape(resolution), bool)
        for s in self.solids():
            rows, cols, mask = solid_cells(s, resolution, inflate, occ.shape)
            occ[rows, cols] |= mask
        return occ

    def reachable_free(self, resolution: float, robot_radius: float = REACH_RADIUS,
                       starts: np.ndarray | None = None) -> np.ndarray:
        """Free cells a robot can reach: (H, W) bool, same raster as :meth:`occupancy`.

        The free space is what is left when the solids are grown by ``robot_radius`` [m] (where
        the robot's centre can go), taken over the 4-connected components that hold a start pose
        (default: all of the world's), and grown back by ``robot_radius`` within the true free
        space, so the cells the robot's body can sweep count as well. This is the denominator of
        an "explored fraction of the reachable free area".
        """
        occ = self.occupancy(resolution)
        labels = free_components(self.occupancy(resolution, inflate=robot_radius))
        starts = self.start_poses if starts is None else np.asarray(starts, float).reshape(-1, 3)
        keep = start_components(labels, starts, resolution)
        reach = np.isin(labels, keep[keep > 0])
        grow = robot_radius + resolution  # one cell more: cell centres sit up to a cell from the solids
        r = int(np.ceil(grow / resolution))
        yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
        disk = (yy ** 2 + xx ** 2) * resolution ** 2 <= grow ** 2
        return ndimage.binary_dilation(reach, structure=disk) & ~occ


def wall_solid(segment, thickness: float, height: float = 0.0, texture: str = "unique", index: int = 0) -> Solid:
    """A wall ``segment`` (x1, y1, x2, y2) [m] as the box it is: ``thickness`` wide [m], capped by
    half of it at both ends."""
    x1, y1, x2, y2 = segment
    length = float(np.hypot(x2 - x1, y2 - y1))
    return Solid(np.array([(x1 + x2) / 2, (y1 + y2) / 2]), np.array([length / 2 + thickness / 2, thickness / 2]),
                 float(np.arctan2(y2 - y1, x2 - x1)), float(height), texture, index)


def solid_cells(solid: Solid, resolution: float, inflate: float,
                shape: tuple[int, int]) -> tuple[slice, slice, np.ndarray]:
    """The cells of a (rows, cols) raster of ``shape`` (the :meth:`World.occupancy` raster)
    whose centres lie inside ``solid`` grown by ``inflate`` [m]: (row slice, column slice, mask
    over that window), the window clipped to the raster (possibly empty)."""
    c, sn = np.cos(solid.yaw), np.sin(solid.yaw)
    hx, hy = solid.half[0] + inflate, solid.half[1] + inflate
    ex, ey = abs(c) * hx + abs(sn) * hy, abs(sn) * hx + abs(c) * hy  # half extents of the bounding box
    x, y = solid.centre
    i0, i1 = max(int(np.floor((y - ey) / resolution)) - 1, 0), min(int(np.ceil((y + ey) / resolution)) + 1, shape[0])
    j0, j1 = max(int(np.floor((x - ex) / resolution)) - 1, 0), min(int(np.ceil((x + ex) / resolution)) + 1, shape[1])
    i1, j1 = max(i1, i0), max(j1, j0)
    gx, gy = np.meshgrid((np.arange(j0, j1) + 0.5) * resolution, (np.arange(i0, i1) + 0.5) * resolution)
    dx, dy = gx - x, gy - y
    mask = (np.abs(c * dx + sn * dy) <= hx) & (np.abs(-sn * dx + c * dy) <= hy)
    return slice(i0, i1), slice(j0, j1), mask


def free_components(blocked: np.ndarray) -> np.ndarray:
    """4-connected components of the cells not ``blocked``: (H, W) int labels, 0 on blocked cells."""
    labels, _ = ndimage.label(~blocked)
    return labels


def start_components(labels: np.ndarray, starts: np.ndarray, resolution: float,
                     reach: float = REACH_RADIUS) -> np.ndarray:
    """The component label (:func:`free_components`) of each start pose (S, 3): that of the free
    cell nearest its position within ``reach`` [m] (a robot standing nearer a wall than the
    clearance still drives off into the free space beside it); 0 where there is none or the pose
    is off the raster."""
    h, w = labels.shape
    ij = np.floor(np.asarray(starts, float)[:, [1, 0]] / resolution).astype(int)
    inside = (ij[:, 0] >= 0) & (ij[:, 0] < h) & (ij[:, 1] >= 0) & (ij[:, 1] < w)
    ij = np.clip(ij, 0, [h - 1, w - 1])
    dist, (ni, nj) = ndimage.distance_transform_edt(labels == 0, return_indices=True)
    near = inside & (dist[ij[:, 0], ij[:, 1]] * resolution <= reach)
    return np.where(near, labels[ni[ij[:, 0], ij[:, 1]], nj[ij[:, 0], ij[:, 1]]], 0)


def _rows(src: str, key: str, rows: Any, cols: int) -> np.ndarray:
    try:
        arr = np.asarray(rows, dtype=float).reshape(-1, cols)
    except (TypeError, ValueError) as exc:
        raise SimError(f"{src}: {key} must be a list of {cols}-number rows") from exc
    if not np.isfinite(arr).all():
        raise SimError(f"{src}: {key} has non-finite values")
    return arr


def _numbers(src: str, key: str, value: Any, n: int) -> list[float]:
    try:
        out = [float(v) for v in value]
    except (TypeError, ValueError) as exc:
        raise SimError(f"{src}: {key} must be {n} numbers") from exc
    if len(out) != n or not np.isfinite(out).all():
        raise SimError(f"{src}: {key} must be {n} finite numbers")
    return out


def _texture(src: str, key: str, value: Any) -> str:
    if value not in TEXTURES:
        raise SimError(f"{src}: {key}: texture must be one of {list(TEXTURES)}, got {value!r}")
    return str(value)


def _parse_walls(src: str, entries: Any, height: float, thickness: float):
    if not isinstance(entries, list) or not entries:
        raise SimError(f"{src}: walls must be a non-empty list")
    segs, hs, ts, texs = [], [], [], []
    for i, e in enumerate(entries):
        key = f"walls[{i}]"
        if isinstance(e, dict):
            extra = sorted(set(e) - {"from", "to", "height", "thickness", "texture"})
            if extra or "from" not in e or "to" not in e:
                raise SimError(f"{src}: {key} needs from, to and optional height, thickness, texture"
                               + (f" (unknown key {extra[0]})" if extra else ""))
            segs.append(_numbers(src, f"{key}.from", e["from"], 2) + _numbers(src, f"{key}.to", e["to"], 2))
            hs.append(float(e.get("height", height)))
            ts.append(float(e.get("thickness", thickness)))
            texs.append(_texture(src, key, e.get("texture", "unique")))
        else:
            try:
                segs.append(_numbers(src, key, e, 4))
            except SimError as exc:
                raise SimError(f"{src}: walls must be a list of 4-number rows or mappings ({key})") from exc
            hs.append(height)
            ts.append(thickness)
            texs.append("unique")
        if hs[-1] <= 0 or ts[-1] <= 0:
            raise SimError(f"{src}: {key}: height and thickness must be > 0")
        if np.hypot(segs[-1][2] - segs[-1][0], segs[-1][3] - segs[-1][1]) <= 0:
            raise SimError(f"{src}: {key} has zero length")
    return np.array(segs), np.array(hs), np.array(ts), texs


def _parse_boxes(src: str, entries: Any):
    if entries is None:
        entries = []
    if not isinstance(entries, list):
        raise SimError(f"{src}: boxes must be a list")
    rows, texs = [], []
    for i, e in enumerate(entries):
        key = f"boxes[{i}]"
        if isinstance(e, dict):
            extra = sorted(set(e) - {"centre", "size", "yaw_deg", "texture"})
            if extra or "centre" not in e or "size" not in e:
                raise SimError(f"{src}: {key} needs centre, size and optional yaw_deg, texture"
                               + (f" (unknown key {extra[0]})" if extra else ""))
            rows.append(_numbers(src, f"{key}.centre", e["centre"], 2) + _numbers(src, f"{key}.size", e["size"], 3)
                        + [float(e.get("yaw_deg", 0.0))])
            texs.append(_texture(src, key, e.get("texture", "unique")))
        else:
            try:
                rows.append(_numbers(src, key, e, 6))
            except SimError as exc:
                raise SimError(f"{src}: boxes must be a list of 6-number rows or mappings ({key})") from exc
            texs.append("unique")
        if min(rows[-1][2:5]) <= 0:
            raise SimError(f"{src}: {key}: sizes must be > 0")
    arr = np.array(rows, float).reshape(-1, 6)
    arr[:, 5] = np.radians(arr[:, 5])
    return arr, texs


def load_world(source: str | Path | dict) -> World:
    """A world: a built-in one by name (``office``, ``small``, ``hall40x30``, ...), a generated one
    by a ``gen:KIND:SEED[:STARTS[:ROBOTS]]`` name (see :mod:`mrslam_core.sim.worldgen`), a world
    YAML file, or a mapping in the YAML format. Every world is checked (:func:`check_world`).

    Raises:
        SimError: unknown name, unreadable file, or a malformed or impossible field (named in the
            message together with the world's file or name).
    """
    if isinstance(source, dict):
        return parse_world(source, str(source.get("name", "<mapping>")))
    if str(source).startswith("gen:"):
        from mrslam_core.sim import worldgen  # it builds on this module

        return parse_world(worldgen.from_name(str(source)), str(source))
    path = Path(source)
    if not path.suffix:
        path = BUILTIN / f"{source}.yaml"
    if not path.is_file():
        have = sorted(q.stem for q in BUILTIN.glob("*.yaml"))
        raise SimError(f"no world {str(source)!r} (built-in worlds: {have}, a gen:KIND:SEED name, or give a YAML path)")
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise SimError(f"{path}: cannot read it as YAML: {exc}") from exc
    if not isinstance(data, dict):
        raise SimError(f"{path}: the top level must be a mapping")
    return parse_world(data, str(path), default_name=path.stem)


def parse_world(data: dict, src: str, default_name: str | None = None) -> World:
    """A world from its YAML mapping; ``src`` names it in error messages; checked by :func:`check_world`."""
    known = {"name", "size", "wall_height", "wall_thickness", "walls", "boxes", "repetitive", "start_poses"}
    unknown = sorted(set(data) - known)
    if unknown:
        raise SimError(f"{src}: unknown key {unknown[0]} (known: {sorted(known)})")
    for key in ("size", "walls", "start_poses"):
        if key not in data:
            raise SimError(f"{src}: missing key {key}")
    size = _numbers(src, "size", data["size"], 2)
    if min(size) <= 0:
        raise SimError(f"{src}: size must be [size_x, size_y] > 0")
    height = float(data.get("wall_height", 2.5))
    thickness = float(data.get("wall_thickness", 0.15))
    walls, heights, thicknesses, wall_tex = _parse_walls(src, data["walls"], height, thickness)
    boxes, box_tex = _parse_boxes(src, data.get("boxes"))
    try:
        repetitive = tuple(int(i) for i in data.get("repetitive") or [])
    except (TypeError, ValueError) as exc:
        raise SimError(f"{src}: repetitive must be a list of wall indices") from exc
    if any(not 0 <= i < len(walls) for i in repetitive):
        raise SimError(f"{src}: repetitive names a wall index outside 0..{len(walls) - 1}")
    for i in repetitive:
        wall_tex[i] = "repetitive"
    repetitive = tuple(i for i, t in enumerate(wall_tex) if t == "repetitive")
    starts = _rows(src, "start_poses", data["start_poses"], 3)
    if not len(starts):
        raise SimError(f"{src}: start_poses is empty")
    outside = (starts[:, 0] < 0) | (starts[:, 0] > size[0]) | (starts[:, 1] < 0) | (starts[:, 1] > size[1])
    if outside.any():
        raise SimError(f"{src}: start_poses[{int(np.argmax(outside))}] lies outside the world")
    world = World(name=str(data.get("name", default_name or src)), size=(size[0], size[1]), wall_height=height,
                  wall_thickness=thickness, walls=walls, boxes=boxes, repetitive=repetitive, start_poses=starts,
                  wall_heights=heights, wall_thicknesses=thicknesses, wall_textures=tuple(wall_tex),
                  box_textures=tuple(box_tex))
    check_world(world, src)
    return world


def check_world(world: World, src: str) -> None:
    """Raise a :class:`SimError` naming the field (``src`` names the world) when two walls overlap
    (run along each other for more than ``OVERLAP_TOLERANCE``, or one crosses the other's
    interior: walls meeting at their ends or in a T are fine), a start pose lies inside a wall or
    box grown by ``ROBOT_HALF_WIDTH``, or a start pose cannot be reached from ``start_poses[0]``
    (``REACH_RADIUS`` clearance on a ``CHECK_RESOLUTION`` raster)."""
    _check_walls(world, src)
    starts = world.start_poses
    for s in world.solids():
        c, sn = np.cos(s.yaw), np.sin(s.yaw)
        dx, dy = starts[:, 0] - s.centre[0], starts[:, 1] - s.centre[1]
        inside = ((np.abs(c * dx + sn * dy) <= s.half[0] + ROBOT_HALF_WIDTH)
                  & (np.abs(-sn * dx + c * dy) <= s.half[1] + ROBOT_HALF_WIDTH))
        if inside.any():
            i = int(np.argmax(inside))
            what = f"walls[{s.index}]" if s.index < len(world.walls) else f"boxes[{s.index - len(world.walls)}]"
            raise SimError(f"{src}: start_poses[{i}] ({starts[i, 0]:g}, {starts[i, 1]:g}) is inside {what} "
                           f"(nearer than the robot's half width {ROBOT_HALF_WIDTH} m)")
    labels = free_components(world.occupancy(CHECK_RESOLUTION, inflate=REACH_RADIUS))
    comp = start_components(labels, starts, CHECK_RESOLUTION)
    bad = np.flatnonzero((comp == 0) | (comp != comp[0]))
    if bad.size:
        i = int(bad[0])
        what = "has no room around it" if comp[i] == 0 else "cannot be reached from start_poses[0]"
        raise SimError(f"{src}: start_poses[{i}] ({starts[i, 0]:g}, {starts[i, 1]:g}) {what} (a robot needs "
                       f"{2 * REACH_RADIUS:g} m of free width to pass)")


def _check_walls(world: World, src: str) -> None:
    """Collinear overlaps and crossings of wall centre lines (see :func:`check_world`)."""
    w = world.walls
    if len(w) < 2:
        return
    p, d = w[:, :2], w[:, 2:] - w[:, :2]
    length = np.linalg.norm(d, axis=1)
    u = d / length[:, None]
    half = world.wall_thicknesses / 2
    for i in range(len(w)):
        j = np.arange(i + 1, len(w))
        if not j.size:
            break
        cross = u[i, 0] * u[j, 1] - u[i, 1] * u[j, 0]
        rel_a, rel_b = p[j] - p[i], p[j] + d[j] - p[i]
        # parallel: both ends of j within the two half thicknesses of i's line, and an overlap along it
        side_a = u[i, 0] * rel_a[:, 1] - u[i, 1] * rel_a[:, 0]
        side_b = u[i, 0] * rel_b[:, 1] - u[i, 1] * rel_b[:, 0]
        along_a, along_b = rel_a @ u[i], rel_b @ u[i]
        overlap = np.minimum(np.maximum(along_a, along_b), length[i]) - np.maximum(np.minimum(along_a, along_b), 0.0)
        close = np.maximum(np.abs(side_a), np.abs(side_b)) < half[i] + half[j]
        hit = (np.abs(cross) < 1e-9) & close & (overlap > OVERLAP_TOLERANCE)
        if hit.any():
            k = int(j[np.argmax(hit)])
            raise SimError(f"{src}: walls[{k}] overlaps walls[{i}] along {overlap[k - i - 1]:.2f} m")
        # crossing: the centre lines meet inside both walls, away from either wall's ends by more
        # than the other's half thickness (so L corners and T junctions pass)
        with np.errstate(divide="ignore", invalid="ignore"):
            s_i = (rel_a[:, 0] * u[j, 1] - rel_a[:, 1] * u[j, 0]) / cross  # along i [m]
            s_j = (rel_a[:, 0] * u[i, 1] - rel_a[:, 1] * u[i, 0]) / cross  # along j [m]
        margin_i, margin_j = half[j] + OVERLAP_TOLERANCE, half[i] + OVERLAP_TOLERANCE
        hit = ((np.abs(cross) >= 1e-9) & (s_i > margin_i) & (s_i < length[i] - margin_i)
               & (s_j > margin_j) & (s_j < length[j] - margin_j))
        if hit.any():
            k = int(j[np.argmax(hit)])
            x, y = p[i] + s_i[k - i - 1] * u[i]
            raise SimError(f"{src}: walls[{k}] crosses walls[{i}] at ({x:.2f}, {y:.2f})")
