"""The landmark maps of all particles: slot-indexed, stored in copy-on-write chunks.

A landmark created for a given observation gets the SAME slot index in every particle that created
it, so one spatial index over slots serves all particles. Slots are grouped in chunks of
``chunk`` consecutive slots. Each particle has a table row naming, per chunk column, the pool chunk
that holds its values (mean, covariance, existence, counts). Resampling copies the table rows
(integers), so a duplicated particle starts out sharing its parent's chunks; the first write to a
shared chunk gives the writer its own copy (copy-on-write). Writing through :meth:`write` is the
only way values change, so no particle ever sees another particle's update — the no-aliasing
guarantee a resampled FastSLAM needs — while a resampling step costs O(M × columns) integers
instead of copying every map (the array form of Montemerlo's log(N) FastSLAM tree sharing).

Per slot (shared by all particles, since the creating observation is the same): descriptor and a
reference position (mean over the particles that hold the slot) for the spatial index.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from mrslam_core.arrays import unique_rows

_FIELDS = ("mean", "cov", "exists", "count", "score")


def _width(pool: np.ndarray) -> int:
    """Values per slot of a pool (P, chunk, ...): 1, dim or dim²."""
    return int(np.prod(pool.shape[2:], dtype=np.int64))


#: per-slot int64 arrays of the store (−1: unknown): the creating track id, stamp and robot
SLOT_IDS = ("origin", "born", "maker")

class LandmarkStore:
    """Landmarks of M particles.

    Attributes:
        dim: landmark dimension (3 for stereo points, 2 for planar landmarks).
        chunk: slots per chunk.
        table: (M, columns) int64 pool chunk of each particle's chunk column.
        pool_mean: (P, chunk, dim) float32 positions in the map frame [m].
        pool_cov: (P, chunk, dim, dim) float32 covariances [m²]. Stored in single precision
            (half the memory traffic of gathers and copy-on-write); all arithmetic on them is
            done in double precision after gathering.
        pool_exists: (P, chunk) bool.
        pool_count: (P, chunk) int32, observations associated (creation included).
        pool_score: (P, chunk) int16, existence counter (001 section III-F).
        refcount: (P,) particles whose table names each pool chunk (0 = free).
        descriptor: (cap, D) float32 per slot.
        ref: (cap, dim) reference position of each slot for the spatial index [m] (inf: none).
        origin: (cap,) track id of the observation that created each slot (-1: unknown).
        born: (cap,) stamp of the update that created each slot [ns] (-1: unknown, e.g. a joined map).
        maker: (cap,) index of the robot whose observation created each slot (-1: unknown).
        size: slots in use (0..size-1).
    """

    def __init__(
        self, num_particles: int, dim: int, descriptor_dim: int = 0, capacity: int = 256, chunk: int = 16
    ):
        self.dim = dim
        self.chunk = chunk
        self.descriptor_dim = descriptor_dim
        self.size = 0
        self.table = np.zeros((num_particles, 0), np.int64)
        self.refcount = np.zeros(0, np.int64)
        self.pool_mean = np.zeros((0, chunk, dim), np.float32)
        self.pool_cov = np.zeros((0, chunk, dim, dim), np.float32)
        self.pool_exists = np.zeros((0, chunk), bool)
        self.pool_count = np.zeros((0, chunk), np.int32)
        self.pool_score = np.zeros((0, chunk), np.int16)
        cap = max(int(capacity), 1)
        self.descriptor = np.zeros((cap, descriptor_dim), np.float32)
        self.ref = np.full((cap, dim), np.inf)
        self.origin = np.full(cap, -1, np.int64)
        self.born = np.full(cap, -1, np.int64)
        self.maker = np.full(cap, -1, np.int64)
        self._tree: cKDTree | None = None
        self._live = np.zeros(0, np.int64)
        self._dtree: cKDTree | None = None
        self._dlive = np.zeros(0, np.int64)
        self._grow_pool(max(cap // chunk, 1) * 2)

    # ------------------------------------------------------------------ sizes
    @property
    def num_particles(self) -> int:
        return self.table.shape[0]

    @property
    def columns(self) -> int:
        return self.table.shape[1]

    def nbytes(self) -> int:
        """Bytes held by the pool chunks in use, the tables and the per-slot arrays."""
        used = int((self.refcount > 0).sum())
        per_chunk = sum(getattr(self, f"pool_{f}")[0:1].nbytes for f in _FIELDS)
        return used * per_chunk + self.table.nbytes + self.descriptor.nbytes + self.ref.nbytes

    # ------------------------------------------------------------------ pool management
    def _grow_pool(self, needed: int) -> None:
        have = self.refcount.size
        if needed <= have:
            return
        new = max(needed, 2 * have)
        extra = new - have

        def pad(a: np.ndarray) -> np.ndarray:
            return np.concatenate([a, np.zeros((extra,) + a.shape[1:], a.dtype)])

        for f in _FIELDS:
            setattr(self, f"pool_{f}", pad(getattr(self, f"pool_{f}")))
        self.refcount = pad(self.refcount)

    def _take_free(self, n: int) -> np.ndarray:
        free = np.flatnonzero(self.refcount == 0)
        if free.size < n:
            self._grow_pool(self.refcount.size + n - free.size)
            free = np.flatnonzero(self.refcount == 0)
        return free[:n]

    def _make_private(self, m: np.ndarray, cols: np.ndarray) -> None:
        """Give particles ``m`` their own copy of chunk columns ``cols`` where they share it."""
        cid = self.table[m, cols]
        shared = self.refcount[cid] > 1
        if not shared.any():
            return
        mask = np.zeros(self.table.size, bool)  # unique (particle, column) keys without sorting
        mask[m[shared] * self.columns + cols[shared]] = True
        key = np.flatnonzero(mask)
        m, cols = key // self.columns, key % self.columns
        cid = self.table[m, cols]
        new = self._take_free(cid.size)
        for f in _FIELDS:
            arr = getattr(self, f"pool_{f}")
            arr[new] = np.take(arr, cid, axis=0)
        self.table[m, cols] = new
        self.refcount[new] = 1
        self.refcount -= np.bincount(cid, minlength=self.refcount.size)

    # ------------------------------------------------------------------ slots
    def allocate(self, n: int, descriptors: np.ndarray | None) -> np.ndarray:
        """Reserve ``n`` new slots (empty in every particle); returns their indices (n,)."""
        if descriptors is not None and self.size == 0 and descriptors.shape[1] != self.descriptor_dim:
            self.descriptor_dim = descriptors.shape[1]
            self.descriptor = np.zeros((self.descriptor.shape[0], self.descriptor_dim), np.float32)
        if descriptors is not None and descriptors.shape[1] != self.descriptor_dim:
            raise ValueError(
                f"descriptor length {descriptors.shape[1]} differs from the map's "
                f"{self.descriptor_dim}"
            )
        slots = np.arange(self.size, self.size + n)
        self.size += n
        if self.size > self.descriptor.shape[0]:
            cap = max(self.size, 2 * self.descriptor.shape[0])
            desc = np.zeros((cap, self.descriptor_dim), np.float32)
            desc[: self.descriptor.shape[0]] = self.descriptor
            ref = np.full((cap, self.dim), np.inf)
            ref[: self.ref.shape[0]] = self.ref
            self.descriptor, self.ref = desc, ref
            for name in SLOT_IDS:
                old = getattr(self, name)
                grown = np.full(cap, -1, np.int64)
                grown[: old.size] = old
                setattr(self, name, grown)
        cols_needed = -(-self.size // self.chunk)
        if cols_needed > self.columns:
            add = cols_needed - self.columns
            fresh = self._take_free(add)  # one empty chunk per new column, shared by all particles
            for f in _FIELDS:
                getattr(self, f"pool_{f}")[fresh] = 0
            self.refcount[fresh] = self.num_particles
            self.table = np.concatenate(
                [self.table, np.broadcast_to(fresh, (self.num_particles, add))], axis=1
            )
        if descriptors is not None and self.descriptor_dim:
            self.descriptor[slots] = descriptors
        return slots

    def gather(self, m: np.ndarray, slots: np.ndarray, fields=("mean", "cov", "exists", "count")):
        """Values of particles ``m`` at ``slots`` (index arrays that broadcast together).

        Returns:
            a tuple of copies, one per name in ``fields`` (default: mean (..., dim),
            cov (..., dim, dim), exists (...), count (...)).
        """
        flat = self.table[m, slots // self.chunk] * self.chunk + slots % self.chunk
        out = []
        for f in fields:
            arr = getattr(self, f"pool_{f}")
            # np.take on rows of a 2-D view: several times faster than fancy indexing of a 4-D pool
            rows = np.take(arr.reshape(arr.shape[0] * arr.shape[1], _width(arr)), flat, axis=0)
            out.append(rows.reshape(flat.shape + arr.shape[2:]))
        return tuple(out)

    def write(self, m: np.ndarray, slots: np.ndarray, **values: np.ndarray) -> None:
        """Set fields (mean, cov, exists, count, score) of particles ``m`` (P,) at ``slots`` (P,).

        Pairs must be unique. Shared chunks are copied first, so only these particles change.
        """
        cols = slots // self.chunk
        self._make_private(m, cols)
        flat = self.table[m, cols] * self.chunk + slots % self.chunk
        for name, value in values.items():
            arr = getattr(self, f"pool_{name}")
            rows = arr.reshape(arr.shape[0] * arr.shape[1], _width(arr))
            rows[flat] = np.reshape(np.broadcast_to(value, flat.shape + arr.shape[2:]), (flat.size, rows.shape[1]))

    def exists_dense(self) -> np.ndarray:
        """(M, size) bool: which particle holds which slot."""
        ex = self.pool_exists[self.table].reshape(self.num_particles, -1)
        return ex[:, : self.size]

    def refresh_reference(self, slots: np.ndarray) -> None:
        """Recompute the reference positions of ``slots`` as the mean over holding particles."""
        if slots.size == 0:
            return
        m = np.arange(self.num_particles)[:, None]
        mean, _, ex, _ = self.gather(m, slots[None, :])
        n = ex.sum(axis=0)
        total = np.einsum("mn,mnd->nd", ex.astype(float), mean)
        with np.errstate(invalid="ignore", divide="ignore"):
            ref = total / n[:, None]
        ref[n == 0] = np.inf
        self.ref[slots] = ref
        self._tree = None
        self._dtree = None

    def set_reference(self, slots: np.ndarray, means: np.ndarray) -> None:
        """Reference positions from values just written: per slot, the mean of ``means`` (P, dim)
        over the pairs that name it (``slots`` (P,)). Cheaper than :meth:`refresh_reference`."""
        if slots.size == 0:
            return
        lo = int(slots.min())  # bincounts over the slot range: no sort (np.unique) needed
        rel = slots - lo
        n = np.bincount(rel)
        uniq = np.flatnonzero(n)
        ref = np.stack([np.bincount(rel, means[:, d], n.size)[uniq] for d in range(self.dim)], -1)
        self.ref[uniq + lo] = ref / n[uniq, None]
        self._tree = None
        self._dtree = None

    def descriptor_candidates(self, desc: np.ndarray, k: int, max_sq_dist: float) -> np.ndarray:
        """Up to ``k`` live slots whose descriptor is within squared distance ``max_sq_dist``
        of each row of ``desc`` (B, D), nearest first: the kd-tree over descriptors of 002
        section III, so association cost grows with log N.

        Returns:
            (B, k) slot indices, -1 where there are fewer.
        """
        if self._dtree is None:
            self._dlive = np.flatnonzero(np.isfinite(self.ref[: self.size, 0]))
            self._dtree = cKDTree(self.descriptor[self._dlive]) if self._dlive.size else None
        out = np.full((desc.shape[0], k), -1, np.int64)
        if self._dtree is None or desc.shape[0] == 0:
            return out
        kk = min(k, self._dlive.size)
        dist, idx = self._dtree.query(desc, k=kk, distance_upper_bound=np.sqrt(max_sq_dist) + 1e-9)
        if kk == 1:
            dist, idx = dist[:, None], idx[:, None]
        ok = np.isfinite(dist)
        out[:, :kk][ok] = self._dlive[idx[ok]]
        return out

    def tree(self) -> cKDTree | None:
        """A kd-tree over the live slots' reference positions (rebuilt only after changes)."""
        if self._tree is None:
            self._live = np.flatnonzero(np.isfinite(self.ref[: self.size, 0]))
            self._tree = cKDTree(self.ref[self._live]) if self._live.size else None
        return self._tree

    def candidates(self, points: np.ndarray, k: int, radius: float) -> np.ndarray:
        """Up to ``k`` slots whose reference lies within ``radius`` of each point, nearest first.

        Args:
            points: (B, dim) query positions in the map frame [m].

        Returns:
            (B, k) slot indices, -1 where there are fewer candidates.
        """
        tree = self.tree()
        out = np.full((points.shape[0], k), -1, np.int64)
        if tree is None or points.shape[0] == 0:
            return out
        kk = min(k, self._live.size)
        dist, idx = tree.query(points, k=kk, distance_upper_bound=radius)
        if kk == 1:
            dist, idx = dist[:, None], idx[:, None]
        ok = np.isfinite(dist)
        out[:, :kk][ok] = self._live[idx[ok]]
        return out

    # ------------------------------------------------------------------ particles
    def copy_rows(self, dst: np.ndarray, src: np.ndarray) -> None:
        """Particles ``dst`` become copies of particles ``src`` (see resampling.copy_plan).

        Only table rows are copied; the chunks they name are shared until written (see
        :meth:`write`), so later updates of one particle never reach another.
        """
        if dst.size == 0:
            return
        self.table[dst] = self.table[src]
        self.refcount[:] = np.bincount(self.table.ravel(), minlength=self.refcount.size)

    def dead_fraction(self) -> float:
        """Share of the used slots that no particle holds any more."""
        if self.size == 0:
            return 0.0
        return 1.0 - float(self.exists_dense().any(axis=0).mean())

    def compact(self) -> np.ndarray:
        """Drop slots no particle holds and renumber the rest densely, keeping chunk sharing.

        Particles whose old chunks feeding a new column are the same share the new chunk.

        Returns:
            (size,) map old slot -> new slot, -1 for dropped slots.
        """
        live = np.flatnonzero(self.exists_dense().any(axis=0))
        remap = np.full(self.size, -1, np.int64)
        remap[live] = np.arange(live.size)
        ncols = -(-live.size // self.chunk)
        old_pool = {f: getattr(self, f"pool_{f}").copy() for f in _FIELDS}
        old_table = self.table
        m_count = self.num_particles
        new_table = np.zeros((m_count, ncols), np.int64)
        self.refcount[:] = 0
        for j in range(ncols):
            src = live[j * self.chunk : (j + 1) * self.chunk]
            src_cols = np.unique(src // self.chunk)
            patterns, owner = unique_rows(old_table[:, src_cols], return_inverse=True)
            ids = self._take_free(patterns.shape[0])
            off = src % self.chunk
            col_of = np.searchsorted(src_cols, src // self.chunk)
            for f in _FIELDS:
                dst = getattr(self, f"pool_{f}")
                vals = old_pool[f][patterns[:, col_of], off[None, :]]
                dst[ids] = 0
                dst[ids, : src.size] = vals
            self.refcount[ids] = np.bincount(owner.ravel(), minlength=ids.size)
            new_table[:, j] = ids[owner.ravel()]
        self.table = new_table
        self.descriptor[: live.size] = self.descriptor[live]
        self.ref[: live.size] = self.ref[live]
        for name in SLOT_IDS:
            arr = getattr(self, name)
            arr[: live.size] = arr[live]
        self.ref[live.size : self.size] = np.inf
        self.size = live.size
        self._tree = None
        self._dtree = None
        return remap

    def particle_map(self, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Landmarks of particle ``m``: (slots (N,), means (N, dim), covs (N, dim, dim), desc (N, D))."""
        slots = np.flatnonzero(self.exists_dense()[m])
        mean, cov, _, _ = self.gather(np.full(slots.size, m), slots)
        return slots, mean, cov, self.descriptor[slots].copy()
