"""Search indexes over the landmark slots whose cost does not grow with the map.

The filter asks, every update, for the slots near an observation (positions) or with a similar
descriptor. A kd-tree rebuilt after each update costs O(N log N) per step: 3.3 ms per robot update
with 20 000 landmarks. These indexes change with what an update changed:

- :class:`PositionGrid`: a hash of square cells in the ground plane, each listing its slots; a slot
  moves between cells only when its reference position leaves its cell. Queries are exact (the
  same slots, nearest first, as a kd-tree over the current positions).
- :class:`DescriptorIndex`: a kd-tree over the descriptors of the slots it was built with, plus a
  brute-force list of the slots added since; descriptors never change, so queries are exact, and
  the tree is rebuilt only when that list has grown.
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy.spatial import cKDTree

_NONE = np.iinfo(np.int64).min  # cell key of a slot that is in no cell
_OFFSET = 1 << 20  # cells are indexed from -2^20: keys (i << 32 | j) stay positive int64


def _cells(xy: np.ndarray, cell: float) -> np.ndarray:
    """Cell indices (..., 2) >= 0 of finite ground positions (..., >=2) [m]; positions beyond
    ±2^20 cells share the edge cells (queries there stay correct, only less selective)."""
    with np.errstate(over="ignore", invalid="ignore"):
        f = np.floor(xy[..., :2] / cell)
        np.maximum(f, -_OFFSET, out=f)  # np.clip's, without its dispatch cost
        np.minimum(f, _OFFSET - 1, out=f)
        return f.astype(np.int64) + _OFFSET


def _keys(xy: np.ndarray, cell: float) -> np.ndarray:
    """(n,) int64 cell keys of ground positions (n, >=2) [m]; _NONE for non-finite ones."""
    out = np.full(xy.shape[0], _NONE, np.int64)
    ok = np.isfinite(xy[:, :2]).all(axis=1)
    ij = _cells(xy[ok], cell)
    out[ok] = (ij[:, 0] << 32) | ij[:, 1]
    return out


class PositionGrid:
    """Slots hashed by the ground-plane cell of their position; exact radius queries.

    Args:
        cell: side of a square cell [m]. Queries visit (2r/cell + 2)² cells; the filter's search
            radius is 0.5-3 m.
    """

    def __init__(self, cell: float = 1.0):
        self.cell = float(cell)
        self.cells: dict[int, list[int]] = {}
        self.key = np.zeros(0, np.int64)

    def update(self, slots: np.ndarray, positions: np.ndarray) -> None:
        """Move ``slots`` (n,) to ``positions`` (n, dim) [m]; a non-finite position removes a slot."""
        if slots.size == 0:
            return
        if slots.max() >= self.key.size:
            grown = np.full(max(int(slots.max()) + 1, 2 * self.key.size), _NONE, np.int64)
            grown[: self.key.size] = self.key
            self.key = grown
        new = _keys(positions, self.cell)
        moved = np.flatnonzero(new != self.key[slots])
        for i in moved.tolist():  # only slots that changed cell: new, removed or crossing a border
            s, k = int(slots[i]), int(new[i])
            old = int(self.key[s])
            if old != _NONE:
                members = self.cells[old]
                members.remove(s)
                if not members:
                    del self.cells[old]
            if k != _NONE:
                self.cells.setdefault(k, []).append(s)
            self.key[s] = k

    def _near(self, lo: list[int], hi: list[int]) -> list[int]:
        """Slots in the cells from ``lo`` to ``hi`` (cell indices, inclusive)."""
        out: list[int] = []
        cells = self.cells
        if (hi[0] - lo[0] + 1) * (hi[1] - lo[1] + 1) > len(cells):  # a wide query: visit the occupied cells
            for key, members in cells.items():
                if lo[0] <= key >> 32 <= hi[0] and lo[1] <= key & 0xFFFFFFFF <= hi[1]:
                    out.extend(members)
            return out
        for i in range(lo[0], hi[0] + 1):
            base = i << 32
            for j in range(lo[1], hi[1] + 1):
                members = cells.get(base | j)
                if members:
                    out.extend(members)
        return out

    def _gather(self, positions: np.ndarray, points: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(slot, query, distance) of every slot in the cells each query's disc touches, and
        possibly of more slots (farther than ``radius``: callers cut by distance)."""
        lo = _cells(points[:, :2] - radius, self.cell)
        hi = _cells(points[:, :2] + radius, self.cell)
        box_lo, box_hi = lo.min(axis=0), hi.max(axis=0)
        if points.shape[0] > 1 and (box_hi - box_lo + 1).prod() <= (hi - lo + 1).prod(axis=1).sum():
            # the queries of one robot update overlap: one visit of their bounding box's cells
            # instead of one per query, then every (query, slot) distance (the same arithmetic
            # per pair as below, so the same values)
            near = np.array(self._near(box_lo.tolist(), box_hi.tolist()), np.int64)
            with np.errstate(over="ignore", invalid="ignore"):
                d = np.sqrt(((positions[near][None] - points[:, None]) ** 2).sum(axis=2))  # (B, S)
                owner, at = np.nonzero(d <= radius)
            return near[at], owner, d[owner, at]
        lo, hi = lo.tolist(), hi.tolist()
        found = [self._near(lo[b], hi[b]) for b in range(points.shape[0])]
        counts = [len(f) for f in found]
        near = np.fromiter(itertools.chain.from_iterable(found), np.int64, sum(counts))
        owner = np.repeat(np.arange(points.shape[0]), counts)
        with np.errstate(over="ignore", invalid="ignore"):  # far-off (bad) positions are never near
            d = np.sqrt(((positions[near] - points[owner]) ** 2).sum(axis=1))
        return near, owner, d

    def nearest(self, positions: np.ndarray, points: np.ndarray, k: int, radius: float) -> np.ndarray:
        """Up to ``k`` slots closer than ``radius`` to each point, nearest first.

        Args:
            positions: (cap, dim) current position of every slot [m] (the one the grid was given).
            points: (B, dim) query positions [m].

        Returns:
            (B, k) slot indices, -1 where there are fewer.
        """
        out = np.full((points.shape[0], k), -1, np.int64)
        if not radius > 0 or k <= 0 or points.shape[0] == 0:
            return out
        near, owner, d = self._gather(positions, points, radius)
        ok = d < radius
        near, owner, d = near[ok], owner[ok], d[ok]
        order = np.lexsort((near, d, owner))  # per query, nearest first
        near, owner = near[order], owner[order]
        rank = np.arange(owner.size) - np.searchsorted(owner, owner)
        keep = rank < k
        out[owner[keep], rank[keep]] = near[keep]
        return out

    def within(self, positions: np.ndarray, point: np.ndarray, radius: float) -> np.ndarray:
        """Sorted slots whose position is within ``radius`` of ``point`` (dim,) [m]."""
        near, _, d = self._gather(positions, np.asarray(point, float)[None], radius)
        return np.sort(near[d <= radius])


class DescriptorIndex:
    """Nearest descriptors among live slots: a kd-tree plus the slots added since it was built.

    Args:
        rebuild_after: rebuild the tree when this many slots were added since the last build,
            or 8·sqrt(n) for a tree of n if that is larger: each added slot costs a brute-force
            distance per query until then, a rebuild O(n log n).
    """

    def __init__(self, rebuild_after: int = 256):
        self.rebuild_after = int(rebuild_after)
        self.tree: cKDTree | None = None
        self.base = np.zeros(0, np.int64)
        self.recent: list[np.ndarray] = []
        self.stale = True

    def add(self, slots: np.ndarray) -> None:
        """Slots (n,) that became live (their descriptors are set and never change)."""
        if slots.size:
            self.recent.append(np.asarray(slots, np.int64))

    def nearest(self, descriptors: np.ndarray, live: np.ndarray, queries: np.ndarray, k: int,
                max_distance: float) -> np.ndarray:
        """Up to ``k`` live slots with a descriptor within ``max_distance`` of each query, nearest first.

        Args:
            descriptors: (cap, D) descriptor of every slot.
            live: (n,) the live slots now (used when the index is rebuilt).
            queries: (B, D).

        Returns:
            (B, k) slot indices, -1 where there are fewer.
        """
        added = np.concatenate(self.recent) if self.recent else np.zeros(0, np.int64)
        if self.stale or added.size > max(self.rebuild_after, 8 * int(np.sqrt(self.base.size))):
            self.base = np.asarray(live, np.int64)
            self.tree = cKDTree(descriptors[self.base]) if self.base.size else None
            self.recent, added, self.stale = [], np.zeros(0, np.int64), False
        b = queries.shape[0]
        out = np.full((b, k), -1, np.int64)
        if b == 0 or k <= 0:
            return out
        slots, dist = [], []
        if self.tree is not None:
            kk = min(k, self.base.size)
            d, i = self.tree.query(queries, k=kk, distance_upper_bound=max_distance)
            d, i = d.reshape(b, kk), i.reshape(b, kk)
            ok = np.isfinite(d)
            slots.append(np.where(ok, self.base[np.minimum(i, self.base.size - 1)], -1))
            dist.append(np.where(ok, d, np.inf))
        if added.size:
            added = np.unique(added)
            d = np.sqrt(((queries[:, None, :] - descriptors[added][None]) ** 2).sum(axis=2))
            ok = d < max_distance
            slots.append(np.where(ok, added[None, :], -1))
            dist.append(np.where(ok, d, np.inf))
        if not slots:
            return out
        s, d = np.concatenate(slots, axis=1), np.concatenate(dist, axis=1)
        order = np.argsort(d, axis=1, kind="stable")[:, :k]
        s, d = np.take_along_axis(s, order, 1), np.take_along_axis(d, order, 1)
        out[:, : s.shape[1]] = np.where(np.isfinite(d), s, -1)
        return out
