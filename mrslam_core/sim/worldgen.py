"""Buildings generated from a seed: offices, ring corridors, open plans and warehouses.

:func:`generate` returns a world mapping in the YAML format of :mod:`mrslam_core.sim.world`
(``load_world`` takes it; ``yaml.safe_dump`` writes it as a world file). Wherever a world is
named, ``gen:KIND:SEED[:STARTS[:ROBOTS]]`` names a generated one, e.g. ``gen:office:7`` or
``gen:ring:3:apart`` (:func:`from_name`).

Kinds (map frame, metres; the longer side along x):

- ``office``: bands of rooms between parallel corridors along x (a cross corridor joins them),
  a door from each room to a corridor, some rooms joined to their neighbour or merged;
- ``ring``: a corridor around a core of rooms, with rooms outside it where the building is large
  enough (else the corridor runs along the outer walls);
- ``open``: one open hall with free-standing partitions, furniture and meeting rooms in corners;
- ``warehouse``: parallel shelving rows (long boxes) with aisles and cross aisles, a free lane
  along the outer walls, an office in a corner.

The size is drawn from ``SIZE_MIN`` up to ``SIZE_MAX`` unless given. Walls are cut into segments of
a few metres, each textured ``unique``, ``repetitive`` (look-alike) or ``plain`` (texture-poor)
by the seed; every world has walls of each. Doors are ``DOOR`` wide (the simulated team plans
with a 0.4 m robot radius). Furniture and partitions keep ``MIN_GAP`` from everything but the wall
they stand against and from the space in front of doors, so no passage is narrower than a robot
planning with that radius can take. Start poses: ``together`` (a zig-zag column, neighbours 1 m
apart, all facing the same way) or ``apart`` (spread over the building), each with
``START_CLEARANCE`` around it in the connected free space.

Deterministic: the layout comes from ``numpy.random.default_rng([seed, kind])`` and the start poses
from a stream of their own, so ``gen:office:7:together`` and ``gen:office:7:apart`` are the same
building.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from mrslam_core.sim.errors import SimError
from mrslam_core.sim.world import Solid, solid_cells, wall_solid

KINDS = ("office", "ring", "open", "warehouse")
START_MODES = ("together", "apart")
#: the range sizes are drawn from, (size_x, size_y) [m]; the smallest size the layouts take
SIZE_MIN = (10.0, 10.0)
SIZE_MAX = (40.0, 30.0)
#: start poses of a generated world whose name does not give a count
ROBOTS = 4
THICKNESS = 0.15  # [m]
HEIGHT = 2.5  # [m]
PARTITION_HEIGHT = 1.6  # free-standing partitions of the open plan [m]
DOOR = (1.3, 1.6)  # door widths [m]
CORRIDOR = (1.8, 2.4)  # corridor widths [m]
ROOM = 4.5  # mean room width along a corridor [m]
SEGMENT = (3.0, 8.0)  # walls are cut into segments this long, one texture each [m]
MIN_GAP = 1.0  # furniture and partitions keep this far from other solids [m]
JAMB = 0.3  # wall kept between a door and a wall joining the same line [m]
START_CLEARANCE = 0.7  # free distance around a start pose [m]
PLAN_RADIUS = 0.45  # the connected free space of the start poses: for a robot of this radius [m]
RES = 0.1  # raster of the placement checks [m]
WALL_TEXTURES = {"unique": 0.6, "repetitive": 0.2, "plain": 0.2}
FURNITURE_TEXTURES = {"unique": 0.7, "repetitive": 0.15, "plain": 0.15}
SHELF_TEXTURES = {"unique": 0.3, "repetitive": 0.5, "plain": 0.2}
#: (along the wall it stands against, depth, height) [m]
WALL_FURNITURE = ((1.4, 0.7, 0.75), (1.0, 0.45, 1.8), (2.0, 0.4, 2.0), (1.8, 0.8, 0.8))
#: free-standing tables (size x, size y, height) [m]
TABLES = ((1.2, 0.8, 0.75), (1.0, 1.0, 0.75), (1.8, 0.9, 0.75))


def generate(kind: str, seed: int, size: tuple[float, float] | None = None, starts: str = "together",
             robots: int = ROBOTS) -> dict:
    """A building of ``kind`` from ``seed``: a world mapping (see :mod:`mrslam_core.sim.world`).

    Args:
        kind: one of ``KINDS``.
        seed: >= 0.
        size: (size_x, size_y) [m], each at least ``SIZE_MIN``; default drawn by the seed.
        starts: ``together`` or ``apart``.
        robots: number of start poses.
    """
    if kind not in KINDS:
        raise SimError(f"world kind must be one of {list(KINDS)}, got {kind!r}")
    if starts not in START_MODES:
        raise SimError(f"start mode must be one of {list(START_MODES)}, got {starts!r}")
    if seed < 0 or robots < 1:
        raise SimError("a generated world needs seed >= 0 and robots >= 1")
    rng = np.random.default_rng([seed, KINDS.index(kind)])
    if size is None:
        sx = _round(rng.uniform(SIZE_MIN[0], SIZE_MAX[0]), 0.5)
        size = (sx, _round(rng.uniform(SIZE_MIN[1], min(SIZE_MAX[1], sx)), 0.5))
    if min(size[0], size[1]) < min(SIZE_MIN) or max(size[0], size[1]) < max(SIZE_MIN):
        raise SimError(f"a generated world is at least {SIZE_MIN[0]:g} x {SIZE_MIN[1]:g} m, got {size}")
    flip = size[1] > size[0]  # lay out along the longer side, then mirror x <-> y
    plan = _Plan((max(size), min(size)), rng)
    {"office": _office, "ring": _ring, "open": _open, "warehouse": _warehouse}[kind](plan)
    plan.furnish()
    poses = _start_poses(plan, starts, robots, np.random.default_rng([seed, KINDS.index(kind), 1]))
    name = f"gen:{kind}:{seed}:{starts}" + (f":{robots}" if robots != ROBOTS else "")
    world = {"name": name, "size": [float(v) for v in plan.size], "wall_height": HEIGHT,
             "wall_thickness": THICKNESS, "walls": plan.walls, "boxes": plan.boxes, "start_poses": poses}
    return _mirror(world) if flip else world


def from_name(name: str) -> dict:
    """The world mapping a ``gen:KIND:SEED[:STARTS[:ROBOTS]]`` name stands for."""
    parts = name.split(":")
    if len(parts) < 3 or len(parts) > 5 or parts[0] != "gen":
        raise SimError(f"world {name!r}: a generated world is named gen:KIND:SEED[:STARTS[:ROBOTS]], "
                       f"KIND one of {list(KINDS)}, STARTS one of {list(START_MODES)}")
    try:
        seed = int(parts[2])
        robots = int(parts[4]) if len(parts) == 5 else ROBOTS
    except ValueError as exc:
        raise SimError(f"world {name!r}: SEED and ROBOTS must be whole numbers") from exc
    try:
        return generate(parts[1], seed, starts=parts[3] if len(parts) > 3 else "together", robots=robots)
    except SimError as exc:
        raise SimError(f"world {name!r}: {exc}") from exc


def suite(count: int) -> list[str]:
    """Names of ``count`` generated worlds: the kinds in turn, seeds 0..count-1, start modes
    alternating so that each kind comes with both (``together`` first)."""
    return [f"gen:{KINDS[i % len(KINDS)]}:{i}:{START_MODES[(i + i // len(KINDS)) % 2]}" for i in range(count)]


def _round(v: float, step: float = 0.05) -> float:
    return float(np.round(v / step) * step)


@dataclass
class _Line:
    """A straight wall along x (``axis`` 0, at y = ``at``) or y (1, at x = ``at``) from ``lo`` to ``hi``."""

    axis: int
    at: float
    lo: float
    hi: float
    gaps: list[tuple[float, float]] = field(default_factory=list)  # doorways along it


class _Plan:
    """A building in the making: wall lines with doorways, rooms, then solids on a raster."""

    def __init__(self, size: tuple[float, float], rng: np.random.Generator):
        self.size, self.rng = size, rng
        w, h = size
        self.lines = [_Line(0, 0.0, 0.0, w), _Line(0, h, 0.0, w), _Line(1, 0.0, 0.0, h), _Line(1, w, 0.0, h)]
        self.rooms: list[tuple[float, float, float, float]] = []  # x0 y0 x1 y1 on wall centre lines
        self.walls: list[dict] = []
        self.boxes: list[dict] = []
        shape = (int(np.ceil(h / RES)), int(np.ceil(w / RES)))
        self.occ = np.zeros(shape, bool)  # solids placed so far
        self.keep_free = np.zeros(shape, bool)  # in front of doors
        self._built = False

    def line(self, axis: int, at: float, lo: float, hi: float) -> int:
        self.lines.append(_Line(axis, _round(at), _round(lo), _round(hi)))
        return len(self.lines) - 1

    def opening(self, k: int, lo: float, hi: float) -> None:
        """A doorway from ``lo`` to ``hi`` along line ``k`` (its ends where walls join it)."""
        self.lines[k].gaps.append((lo, hi))

    def door(self, k: int, lo: float, hi: float) -> bool:
        """A door of a drawn width on line ``k`` between ``lo`` and ``hi``, away from the walls
        joining the line; False where there is no room for one."""
        ln = self.lines[k]
        lo, hi = max(lo, ln.lo), min(hi, ln.hi)
        width = min(self.rng.uniform(*DOOR), hi - lo - 2 * JAMB)
        if width < DOOR[0]:
            return False
        joints = self._joints(k)
        for _ in range(20):
            centre = self.rng.uniform(lo + JAMB + width / 2, hi - JAMB - width / 2)
            a, b = _round(centre - width / 2), _round(centre + width / 2)
            if not any(a - JAMB < j < b + JAMB for j in joints) and not any(a < g1 and g0 < b for g0, g1 in ln.gaps):
                ln.gaps.append((a, b))
                return True
        return False

    def room(self, x0: float, y0: float, x1: float, y1: float) -> None:
        self.rooms.append((x0, y0, x1, y1))

    def _joints(self, k: int) -> list[float]:
        """Positions along line ``k`` where another line ends on it or crosses it."""
        ln = self.lines[k]
        out = []
        for m in self.lines:
            if m.axis != ln.axis and ln.lo < m.at < ln.hi and m.lo - 1e-6 <= ln.at <= m.hi + 1e-6:
                out.append(m.at)
        return out

    def build_walls(self) -> None:
        """Cut every line at its joints, at drawn intervals and around its doorways into wall
        segments with drawn textures; raster them and keep the space in front of doors free."""
        for k, ln in enumerate(self.lines):
            cuts = {ln.lo, ln.hi, *self._joints(k)}
            pos = ln.lo
            while True:
                pos += self.rng.uniform(*SEGMENT)
                if pos >= ln.hi - SEGMENT[0] / 2:
                    break
                cuts.add(_round(pos))
            cuts = sorted(cuts)
            for a, b in zip(cuts[:-1], cuts[1:]):
                for p, q in _minus((a, b), ln.gaps):
                    seg = [p, ln.at, q, ln.at] if ln.axis == 0 else [ln.at, p, ln.at, q]
                    self._add_wall(seg, _draw_texture(self.rng, WALL_TEXTURES))
            for g0, g1 in ln.gaps:
                c, half = ((g0 + g1) / 2, ln.at), ((g1 - g0) / 2, THICKNESS / 2 + MIN_GAP)
                centre = np.array(c if ln.axis == 0 else c[::-1])
                _paint(self.keep_free, Solid(centre, np.array(half), ln.axis * np.pi / 2, 0.0, "", 0))
        textures = [e["texture"] for e in self.walls]
        for need in ("unique", "plain", "repetitive"):  # every world has walls of each
            if need not in textures:  # taken from a texture that more walls have
                spare = [k for k, t in enumerate(textures) if textures.count(t) > 1]
                k = spare[int(self.rng.integers(len(spare)))]
                self.walls[k]["texture"] = textures[k] = need
        self._built = True

    def _add_wall(self, seg: list[float], texture: str, height: float | None = None) -> None:
        seg = [_round(v, 0.01) for v in seg]
        entry = {"from": seg[:2], "to": seg[2:], "texture": texture}
        if height is not None:
            entry["height"] = height
        self.walls.append(entry)
        _paint(self.occ, wall_solid(seg, THICKNESS))

    def fits(self, solid: Solid, back: np.ndarray | None = None) -> bool:
        """Whether ``solid`` keeps ``MIN_GAP`` from every solid so far and from the space in front
        of doors; ``back`` (2,), the unit normal of the wall it stands against (pointing away from
        it): what lies behind its back face does not count."""
        rows, cols, near = solid_cells(solid, RES, MIN_GAP, self.occ.shape)
        if back is not None:
            gx, gy = np.meshgrid((np.arange(cols.start, cols.stop) + 0.5) * RES,
                                 (np.arange(rows.start, rows.stop) + 0.5) * RES)
            c, s = np.cos(solid.yaw), np.sin(solid.yaw)
            half_depth = (abs(c * back[0] + s * back[1]) * solid.half[0]
                          + abs(-s * back[0] + c * back[1]) * solid.half[1])
            near &= (gx - solid.centre[0]) * back[0] + (gy - solid.centre[1]) * back[1] > -half_depth + RES / 2
        return not (near & (self.occ[rows, cols] | self.keep_free[rows, cols])).any()

    def partition(self, seg: list[float]) -> bool:
        """A free-standing wall, if it fits."""
        solid = wall_solid(seg, THICKNESS)
        if not self.fits(solid):
            return False
        self._add_wall(seg, _draw_texture(self.rng, WALL_TEXTURES), PARTITION_HEIGHT)
        return True

    def box(self, centre, size, yaw_deg: float, textures: dict, back: np.ndarray | None = None) -> bool:
        """A box (size x, y, z [m]) standing on the floor, if it fits."""
        solid = Solid(np.asarray(centre, float), np.array(size[:2]) / 2, np.radians(yaw_deg), size[2], "", 0)
        if not self.fits(solid, back):
            return False
        self.boxes.append({"centre": [_round(v, 0.01) for v in centre], "size": [float(v) for v in size],
                           "yaw_deg": float(yaw_deg), "texture": _draw_texture(self.rng, textures)})
        _paint(self.occ, solid)
        return True

    def furnish(self) -> None:
        """Furniture in every room: against its walls and, in large rooms, free-standing tables."""
        if not self._built:
            self.build_walls()
        rng = self.rng
        t = THICKNESS / 2
        for x0, y0, x1, y1 in self.rooms:
            area = (x1 - x0) * (y1 - y0)
            target = 1 + rng.poisson(area / 20)
            placed = 0
            for _ in range(8 * target):
                if placed >= target:
                    break
                if rng.random() < 0.75 or area < 20:
                    along, depth, height = WALL_FURNITURE[rng.integers(len(WALL_FURNITURE))]
                    side = int(rng.integers(4))  # bottom, top, left, right
                    back = np.array([[0, 1], [0, -1], [1, 0], [-1, 0]][side], float)
                    lo, hi = (x0, x1) if side < 2 else (y0, y1)
                    if hi - lo < along + 2 * t:
                        continue
                    s = rng.uniform(lo + t + along / 2, hi - t - along / 2)
                    face = [y0 + t, y1 - t, x0 + t, x1 - t][side]
                    off = face + (depth / 2 if side in (0, 2) else -depth / 2)
                    centre = (s, off) if side < 2 else (off, s)
                    placed += self.box(centre, (along, depth, height), 0.0 if side < 2 else 90.0,
                                       FURNITURE_TEXTURES, back)
                else:
                    sx, sy, sz = TABLES[rng.integers(len(TABLES))]
                    margin = MIN_GAP + t + np.hypot(sx, sy) / 2
                    if x1 - x0 < 2 * margin or y1 - y0 < 2 * margin:
                        continue
                    centre = (rng.uniform(x0 + margin, x1 - margin), rng.uniform(y0 + margin, y1 - margin))
                    placed += self.box(centre, (sx, sy, sz), float(rng.choice([0, 30, 45, 60, 90])), FURNITURE_TEXTURES)


def _paint(raster: np.ndarray, solid: Solid) -> None:
    rows, cols, mask = solid_cells(solid, RES, 0.0, raster.shape)
    raster[rows, cols] |= mask


def _minus(span: tuple[float, float], gaps: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """The parts of ``span`` outside every gap."""
    parts = [span]
    for g0, g1 in gaps:
        parts = [q for a, b in parts for q in ((a, min(b, g0)), (max(a, g1), b)) if q[1] - q[0] > 1e-6]
    return parts


def _draw_texture(rng: np.random.Generator, p: dict[str, float]) -> str:
    return str(rng.choice(list(p), p=list(p.values())))


def _split(rng: np.random.Generator, lo: float, hi: float, mean: float = ROOM) -> list[float]:
    """Positions cutting [lo, hi] into rooms of about ``mean`` (0.7-1.3 times it), ends included."""
    n = max(1, int(round((hi - lo) / mean)))
    widths = rng.uniform(0.7, 1.3, n)
    cuts = lo + np.concatenate([[0.0], np.cumsum(widths / widths.sum())]) * (hi - lo)
    return [lo] + [_round(c) for c in cuts[1:-1]] + [hi]


def _office(plan: _Plan) -> None:
    """Bands of rooms between corridors along x; a cross corridor joins the corridors."""
    w, h = plan.size
    rng = plan.rng
    c = _round(rng.uniform(*CORRIDOR))
    n = 1
    while (h - n * c) / (n + 1) > 7.0:
        n += 1
    d = (h - n * c) / (n + 1)
    bands = [(_round(k * (d + c)), _round(k * (d + c) + d)) for k in range(n)] + [(_round(n * (d + c)), h)]
    below = [plan.line(0, b1, 0.0, w) for _, b1 in bands[:-1]]  # corridor k's south wall
    above = [plan.line(0, b0, 0.0, w) for b0, _ in bands[1:]]  # corridor k's north wall
    spine = _round(rng.uniform(0.2 * w, 0.8 * w - c)) if n > 1 else None
    for k, (b0, b1) in enumerate(bands):
        doors = ([above[k - 1]] if k > 0 else []) + ([below[k]] if k < n else [])
        crossing = (spine, spine + c) if spine is not None and 0 < k < n else ()  # the cross corridor's walls
        if crossing:
            cuts = _split(rng, 0.0, spine) + _split(rng, spine + c, w)
            for ln in doors:
                plan.opening(ln, spine, spine + c)
        else:
            cuts = _split(rng, 0.0, w)
        # the others merge two rooms
        walls = {x: plan.line(1, x, b0, b1) for x in sorted(set(cuts))[1:-1] if x in crossing or rng.random() > 0.15}
        edges = [0.0, *walls, w]
        for x0, x1 in zip(edges[:-1], edges[1:]):
            if (x0, x1) == crossing:
                continue
            plan.room(x0, b0, x1, b1)
            first = int(rng.integers(len(doors)))
            plan.door(doors[first], x0, x1)
            if len(doors) > 1 and rng.random() < 0.3:
                plan.door(doors[1 - first], x0, x1)
        for x, ln in walls.items():  # some neighbours share a door
            if x not in crossing and rng.random() < 0.2:
                plan.door(ln, b0, b1)


def _ring(plan: _Plan) -> None:
    """A corridor around a core of rooms; rooms outside it along the sides long enough."""
    w, h = plan.size
    rng = plan.rng
    c = _round(rng.uniform(*CORRIDOR))
    a = _round(rng.uniform(3.0, 5.0))
    ax = a if w - 2 * a - 2 * c >= 4.0 else 0.0
    ay = a if h - 2 * a - 2 * c >= 4.0 else 0.0
    x0, y0, x1, y1 = ax + c, ay + c, w - ax - c, h - ay - c  # the core
    if ay:
        for yb, band, ln in ((0.0, ay, plan.line(0, ay, 0.0, w)), (h - ay, h, plan.line(0, h - ay, 0.0, w))):
            cuts = [0.0] + _split(rng, ax, w - ax)[1:-1] + [w]
            for x in cuts[1:-1]:
                plan.line(1, x, yb, band)
            for r0, r1 in zip(cuts[:-1], cuts[1:]):
                plan.room(r0, yb, r1, band)
                plan.door(ln, max(r0, ax), min(r1, w - ax))
    if ax:
        for xb, band, ln in ((0.0, ax, plan.line(1, ax, ay, h - ay)), (w - ax, w, plan.line(1, w - ax, ay, h - ay))):
            cuts = _split(rng, ay, h - ay)
            for y in cuts[1:-1]:
                plan.line(0, y, xb, band)
            for r0, r1 in zip(cuts[:-1], cuts[1:]):
                plan.room(xb, r0, band, r1)
                plan.door(ln, r0, r1)
    south, north = plan.line(0, y0, x0, x1), plan.line(0, y1, x0, x1)
    west, east = plan.line(1, x0, y0, y1), plan.line(1, x1, y0, y1)
    rows = [(y0, y1)] if y1 - y0 <= 9.0 else [(y0, _round((y0 + y1) / 2)), (_round((y0 + y1) / 2), y1)]
    if len(rows) == 2:
        plan.line(0, rows[0][1], x0, x1)
    for r, (r0, r1) in enumerate(rows):
        cuts = _split(rng, x0, x1)
        walls = [x for x in cuts[1:-1] if rng.random() > 0.15]
        for x in walls:
            plan.line(1, x, r0, r1)
        edges = [x0] + walls + [x1]
        for k, (e0, e1) in enumerate(zip(edges[:-1], edges[1:])):
            plan.room(e0, r0, e1, r1)
            outward = [south] if len(rows) == 2 and r == 0 else [north] if len(rows) == 2 else [south, north]
            if k == 0 and rng.random() < 0.3:
                plan.door(west, r0, r1)
            elif k == len(edges) - 2 and rng.random() < 0.3:
                plan.door(east, r0, r1)
            else:
                plan.door(outward[int(rng.integers(len(outward)))], e0, e1)


def _corner_room(plan: _Plan, corner: int, size: tuple[float, float]) -> None:
    """A room in corner 0-3 (SW, SE, NW, NE) with a door in one of its two inner walls."""
    w, h = plan.size
    rw, rh = size
    x0, x1 = (0.0, rw) if corner in (0, 2) else (w - rw, w)
    y0, y1 = (0.0, rh) if corner in (0, 1) else (h - rh, h)
    xi = x1 if corner in (0, 2) else x0
    yi = y1 if corner in (0, 1) else y0
    side = plan.line(1, xi, y0, y1)
    front = plan.line(0, yi, x0, x1)
    plan.room(x0, y0, x1, y1)
    if plan.rng.random() < 0.5:
        plan.door(side, y0, y1)
    else:
        plan.door(front, x0, x1)


def _open(plan: _Plan) -> None:
    """One hall: meeting rooms in some corners, free-standing partitions, furniture."""
    w, h = plan.size
    rng = plan.rng
    corners = rng.permutation(4)[:int(rng.integers(0, 3)) if w * h >= 200 else 0]
    for corner in corners:
        _corner_room(plan, int(corner), (_round(rng.uniform(3.0, 5.0)), _round(rng.uniform(3.0, 4.5))))
    plan.build_walls()
    for _ in range(40):
        if sum("height" in e for e in plan.walls) >= 2 + int(w * h // 80):
            break
        length, along_x = rng.uniform(1.5, 4.0), rng.random() < 0.5
        cx, cy = rng.uniform(MIN_GAP, w - MIN_GAP), rng.uniform(MIN_GAP, h - MIN_GAP)
        half = length / 2
        plan.partition([cx - half, cy, cx + half, cy] if along_x else [cx, cy - half, cx, cy + half])
    plan.room(0.0, 0.0, w, h)  # the hall: furniture along the outer walls and tables in the open


def _warehouse(plan: _Plan) -> None:
    """Shelving rows along the longer side, aisles between them, cross aisles, an office in a corner."""
    w, h = plan.size
    rng = plan.rng
    if w * h >= 150 and rng.random() < 0.6:
        _corner_room(plan, int(rng.integers(4)), (_round(rng.uniform(3.5, 5.0)), _round(rng.uniform(3.0, 4.0))))
    plan.build_walls()
    lane, aisle = rng.uniform(1.8, 2.5), rng.uniform(1.8, 2.6)
    depth, height = _round(rng.uniform(0.8, 1.2)), _round(rng.uniform(2.0, 2.5))
    y = lane + depth / 2
    while y + depth / 2 <= h - lane:
        x = lane
        while x < w - lane - 1.0:
            length = min(rng.uniform(6.0, 12.0), w - lane - x)
            plan.box((x + length / 2, y), (_round(length), depth, height), 0.0, SHELF_TEXTURES)
            x += length + rng.uniform(2.0, 3.0)  # a cross aisle
        y += depth + aisle
    for _ in range(int(w * h // 100)):  # pallets in the lanes
        plan.box((rng.uniform(1.0, w - 1.0), rng.uniform(1.0, h - 1.0)),
                 (1.2, 1.0, _round(rng.uniform(0.4, 1.4))), float(rng.choice([0, 90])), FURNITURE_TEXTURES)


def _start_poses(plan: _Plan, mode: str, robots: int, rng: np.random.Generator) -> list[list[float]]:
    """``robots`` start poses x, y, θ [m, m, rad] in the largest connected free space."""
    clear = ndimage.distance_transform_edt(~plan.occ) * RES  # from each cell centre to the nearest solid cell
    labels, n = ndimage.label(clear > PLAN_RADIUS)
    if not n:
        raise SimError("generated world has no free space")  # a layout bug, not a user's mistake
    main = labels == np.argmax(np.bincount(labels.ravel())[1:]) + 1
    ok = main & (clear >= START_CLEARANCE)

    def free(xy: np.ndarray) -> bool:
        i, j = int(xy[1] / RES), int(xy[0] / RES)
        return 0 <= i < ok.shape[0] and 0 <= j < ok.shape[1] and bool(ok[i, j])

    def ray(xy: np.ndarray, theta: float, cap: float = 5.0) -> float:
        u = np.array([np.cos(theta), np.sin(theta)])
        for r in np.arange(RES, cap, RES):
            i, j = int((xy[1] + r * u[1]) / RES), int((xy[0] + r * u[0]) / RES)
            if not (0 <= i < clear.shape[0] and 0 <= j < clear.shape[1]) or clear[i, j] < PLAN_RADIUS:
                return float(r)
        return cap

    def heading(xy: np.ndarray, at_least: float = 0.0) -> list[float]:
        """Headings (8 directions) with at least this much free length ahead [m], the longest
        first, ties in drawn order: a camera facing a wall at arm's length sees little."""
        thetas = np.arange(8) * np.pi / 4 - np.pi
        lengths = np.array([ray(xy, t) for t in thetas])
        order = np.argsort(-(lengths + rng.uniform(0, 0.01, 8)))
        return [float(thetas[k]) for k in order if lengths[k] >= at_least]

    cells = np.argwhere(ok)
    centres = (cells[:, ::-1] + 0.5) * RES
    order = rng.permutation(len(centres))
    if mode == "together":
        for ahead in (3.0, 1.5):  # free length ahead of the column [m]: a long view where there is one
            for k in order[:300]:
                anchor = centres[k]
                for theta in heading(anchor, ahead):
                    u = np.array([np.cos(theta), np.sin(theta)])
                    v = np.array([-u[1], u[0]])
                    column = [anchor - 0.8 * i * u + (0.3 if i % 2 == 0 else -0.3) * v for i in range(robots)]
                    if all(free(p) for p in column):
                        return [[_round(p[0], 0.01), _round(p[1], 0.01), round(theta, 4)] for p in column]
        raise SimError(f"no room for {robots} robots together in the generated world")
    chosen = [centres[order[0]]]
    while len(chosen) < robots:
        d = np.min(np.linalg.norm(centres[:, None] - np.array(chosen)[None], axis=2), axis=1)
        far = np.flatnonzero(d >= 0.85 * d.max())
        chosen.append(centres[rng.choice(far)])
    return [[_round(p[0], 0.01), _round(p[1], 0.01), round(heading(p)[0], 4)] for p in chosen]


def _mirror(world: dict) -> dict:
    """The world mirrored about x = y (its size swapped)."""
    def swap(xy):
        return [xy[1], xy[0]]

    return dict(world, size=swap(world["size"]),
                walls=[dict(e, **{"from": swap(e["from"]), "to": swap(e["to"])}) for e in world["walls"]],
                boxes=[dict(b, centre=swap(b["centre"]), yaw_deg=90.0 - b["yaw_deg"]) for b in world["boxes"]],
                start_poses=[[p[1], p[0], round(float((np.pi / 2 - p[2] + np.pi) % (2 * np.pi) - np.pi), 4)]
                             for p in world["start_poses"]])
