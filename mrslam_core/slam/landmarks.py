"""The landmark maps of all particles: slot-indexed, stored in a two-level copy-on-write tree.

A landmark created for a given observation gets the SAME slot index in every particle that created
it, so one spatial index over slots serves all particles. Slots are grouped in chunks of ``chunk``
consecutive slots, and chunk columns in nodes of ``fanout`` columns. Each particle has a table row
naming, per node column, the node that lists its chunks; a chunk holds the values (mean,
covariance, existence, counts) of its slots. Resampling copies table rows, so a duplicated particle
starts out sharing its parent's nodes; the first write to a shared node or chunk gives the writer
its own copy (copy-on-write). Writing through :meth:`write` is the only way values change, so no
particle ever sees another particle's update — the no-aliasing guarantee a resampled FastSLAM needs
— while a resampling step costs O(M × N / (chunk × fanout)) integers instead of copying every map
(the array form of Montemerlo's log(N) FastSLAM tree, with two levels). Nodes and chunks are
reference-counted and recycled through free lists, so no step scans the pool. Chunk 0 is the
empty chunk every unwritten column names; it is never written (a write copies it first). The
per-pair work (pool rows, copy-on-write, the write itself) is compiled
(:mod:`mrslam_core.slam.store_kernels`): a write copies a pair's shared chunk and writes its
values in one pass, while the chunk is in cache.

Per slot (shared by all particles, since the creating observation is the same): descriptor and a
reference position (mean over the particles that hold the slot) for the search indexes
(:mod:`mrslam_core.slam.spatial_index`).
"""

from __future__ import annotations

import math

import numpy as np

from mrslam_core.arrays import unique_rows
from mrslam_core.slam import store_kernels as kernels
from mrslam_core.slam.spatial_index import DescriptorIndex, PositionGrid

_FIELDS = ("mean", "cov", "exists", "count", "score")
_EMPTY = 0  # the pool chunk every unwritten chunk column names (pinned: never freed, never written)


#: the type each field's values are handed to the write kernel in (cast to the pool's on writing)
_VALUE_TYPES = {"mean": np.float64, "cov": np.float64, "exists": np.bool_, "count": np.int64, "score": np.int64}


def _width(pool: np.ndarray) -> int:
    """Values per slot of a pool (P, chunk, ...): 1, dim or dim²."""
    return int(np.prod(pool.shape[2:], dtype=np.int64))


#: per-slot int64 arrays of the store (−1: unknown): the creating track id, stamp and robot
SLOT_IDS = ("origin", "born", "maker")
#: the arrays that hold the store's state (:meth:`LandmarkStore.state`)
STATE_ARRAYS = ("table", "nodes", "node_ref", "refcount") + tuple(f"pool_{f}" for f in _FIELDS) + (
    "descriptor", "ref") + SLOT_IDS


class _FreeList:
    """A stack of free ids (nodes or pool chunks): ``ids[:top]``, the top last."""

    def __init__(self) -> None:
        self.buf = np.zeros(0, np.int64)
        self.top = 0

    @property
    def ids(self) -> np.ndarray:
        return self.buf[: self.top]

    def push(self, ids: np.ndarray) -> None:
        if ids.size:
            if self.top + ids.size > self.buf.size:
                grown = np.zeros(max(self.top + ids.size, 2 * self.buf.size), np.int64)
                grown[: self.top] = self.buf[: self.top]
                self.buf = grown
            self.buf[self.top : self.top + ids.size] = ids
            self.top += ids.size

    def pop(self, n: int) -> np.ndarray:
        self.top -= n
        return self.buf[self.top : self.top + n].copy()


class LandmarkStore:
    """Landmarks of M particles.

    Attributes:
        dim: landmark dimension (3 for stereo points, 2 for planar landmarks).
        chunk: slots per chunk.
        fanout: chunk columns per node.
        table: (M, G) int64 node of each particle's node column.
        nodes: (Q, fanout) int64 pool chunk of each of a node's chunk columns.
        node_ref: (Q,) table entries naming each node (0 = free).
        pool_mean: (P, chunk, dim) float32 positions in the map frame [m].
        pool_cov: (P, chunk, dim, dim) float32 covariances [m²]. Stored in single precision
            (half the memory traffic of gathers and copy-on-write); all arithmetic on them is
            done in double precision after gathering.
        pool_exists: (P, chunk) bool.
        pool_count: (P, chunk) int32, observations associated (creation included).
        pool_score: (P, chunk) int16, existence counter (001 section III-F).
        refcount: (P,) entries of live nodes naming each pool chunk (0 = free; chunk 0 pinned).
        descriptor: (cap, D) float32 per slot.
        ref: (cap, dim) reference position of each slot for the spatial index [m] (inf: none).
        origin: (cap,) track id of the observation that created each slot (-1: unknown).
        born: (cap,) stamp of the update that created each slot [ns] (-1: unknown, e.g. a joined map).
        maker: (cap,) index of the robot whose observation created each slot (-1: unknown).
        size: slots in use (0..size-1).
    """

    def __init__(
        self, num_particles: int, dim: int, descriptor_dim: int = 0, capacity: int = 256, chunk: int = 16,
        fanout: int = 32,
    ):
        self.dim = dim
        self.chunk = chunk
        self.fanout = fanout
        self.descriptor_dim = descriptor_dim
        self.size = 0
        self.table = np.zeros((num_particles, 0), np.int64)
        self.nodes = np.zeros((0, fanout), np.int64)
        self.node_ref = np.zeros(0, np.int64)
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
        self._free_chunks = _FreeList()
        self._free_nodes = _FreeList()
        self._scratch = np.zeros(0, np.int64)
        self._grow_pool(max(cap // chunk, 1) * 2)
        self.refcount[_EMPTY] = 1  # the pin
        self._grow_nodes(max(cap // (chunk * fanout), 1) * 2)
        self._reset_indexes()

    # ------------------------------------------------------------------ sizes
    @property
    def num_particles(self) -> int:
        return self.table.shape[0]

    @property
    def columns(self) -> int:
        """Chunk columns in use."""
        return -(-self.size // self.chunk)

    def nbytes(self) -> int:
        """Bytes held by the pool chunks and nodes in use, the table and the per-slot arrays."""
        used = int((self.refcount > 0).sum())
        per_chunk = sum(getattr(self, f"pool_{f}")[0:1].nbytes for f in _FIELDS)
        nodes = int((self.node_ref > 0).sum()) * self.nodes[0:1].nbytes
        return used * per_chunk + nodes + self.table.nbytes + self.descriptor.nbytes + self.ref.nbytes

    # ------------------------------------------------------------------ pool and node management
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
        self._free_chunks.push(np.arange(new - 1, max(have, 1) - 1, -1))  # low ids on top

    def _grow_nodes(self, needed: int) -> None:
        have = self.node_ref.size
        if needed <= have:
            return
        new = max(needed, 2 * have)
        self.nodes = np.concatenate([self.nodes, np.zeros((new - have, self.fanout), np.int64)])
        self.node_ref = np.concatenate([self.node_ref, np.zeros(new - have, np.int64)])
        self._free_nodes.push(np.arange(new - 1, have - 1, -1))

    def _reserve_chunks(self, n: int) -> None:
        """Grow the pool so that ``n`` chunks are free."""
        if self._free_chunks.top < n:
            self._grow_pool(self.refcount.size + n - self._free_chunks.top)

    def _reserve_nodes(self, n: int) -> None:
        """Grow the nodes so that ``n`` are free."""
        if self._free_nodes.top < n:
            self._grow_nodes(self.node_ref.size + n - self._free_nodes.top)

    def _take_nodes(self, n: int) -> np.ndarray:
        self._reserve_nodes(n)
        return self._free_nodes.pop(n)

    def _release_chunks(self, cid: np.ndarray) -> None:
        """Drop one reference to each entry of ``cid`` (repeats allowed); free those left with none."""
        if cid.size == 0:
            return
        self._free_chunks.push(np.sort(kernels.release(self.refcount, np.ascontiguousarray(cid, np.int64))))

    def _free_dead_nodes(self, dead: np.ndarray) -> None:
        """Free the nodes ``dead`` (no table entry names them any more; any order) and drop their
        references to their chunks."""
        if dead.size:
            dead = np.sort(dead)
            self._free_nodes.push(dead)
            self._release_chunks(self.nodes[dead].ravel())

    def _scratch_for(self, space: int) -> np.ndarray:
        """A scratch array of at least ``space`` entries, all −1 (the kernels leave it so)."""
        if self._scratch.size < space:
            self._scratch = np.full(max(space, 2 * self._scratch.size), -1, np.int64)
        return self._scratch

    def chunk_table(self) -> np.ndarray:
        """(M, columns) pool chunk of each particle's chunk column (a new array)."""
        eff = self.nodes[self.table].reshape(self.num_particles, -1)
        return eff[:, : self.columns]

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
        groups = -(-self.columns // self.fanout)
        if groups > self.table.shape[1]:
            add = groups - self.table.shape[1]
            fresh = self._take_nodes(add)  # one empty node per new node column, shared by all particles
            self.nodes[fresh] = _EMPTY
            self.node_ref[fresh] = self.num_particles
            self.refcount[_EMPTY] += add * self.fanout
            self.table = np.concatenate(
                [self.table, np.broadcast_to(fresh, (self.num_particles, add))], axis=1
            )
        if descriptors is not None and self.descriptor_dim:
            self.descriptor[slots] = descriptors
        return slots

    def rows(self, m: np.ndarray, slots: np.ndarray) -> np.ndarray:
        """Rows in the pools' (P·chunk, ...) views of the pairs (particles ``m``, ``slots``), index
        arrays that broadcast together; (M, V) for ``m`` = arange(M)[:, None], ``slots`` (1, V)."""
        m, slots = np.asarray(m, np.int64), np.asarray(slots, np.int64)
        if m.shape == (self.num_particles, 1) and slots.ndim == 2 and slots.shape[0] == 1 and (
            np.array_equal(m[:, 0], np.arange(m.shape[0]))
        ):
            out = np.empty((m.shape[0], slots.shape[1]), np.int64)
            cols, which = np.unique(slots[0] // self.chunk, return_inverse=True)
            kernels.pool_rows_outer(self.table, self.nodes, self.chunk, self.fanout, cols, which.ravel(),
                                    slots[0] % self.chunk, out)
            return out
        m, slots = np.broadcast_arrays(m, slots)
        out = np.empty(m.shape, np.int64)
        kernels.pool_rows(self.table, self.nodes, self.chunk, self.fanout, m.ravel(), slots.ravel(), out.reshape(-1))
        return out

    def field_rows(self, name: str) -> np.ndarray:
        """The pool of field ``name`` as rows (P·chunk, values per slot), a view."""
        arr = getattr(self, f"pool_{name}")
        return arr.reshape(arr.shape[0] * arr.shape[1], _width(arr))

    def gather(self, m: np.ndarray, slots: np.ndarray, fields=("mean", "cov", "exists", "count")):
        """Values of particles ``m`` at ``slots`` (index arrays that broadcast together).

        Returns:
            a tuple of copies, one per name in ``fields`` (default: mean (..., dim),
            cov (..., dim, dim), exists (...), count (...)).
        """
        return self.gather_rows(self.rows(m, slots), fields)

    def gather_rows(self, rows: np.ndarray, fields=("mean", "cov", "exists", "count")):
        """Values at pool ``rows`` (see :meth:`rows`), one copy per name in ``fields``."""
        out = []
        for f in fields:
            arr = getattr(self, f"pool_{f}")
            # np.take on rows of a 2-D view: several times faster than fancy indexing of a 4-D pool
            out.append(np.take(self.field_rows(f), rows, axis=0).reshape(rows.shape + arr.shape[2:]))
        return tuple(out)

    def write(self, m: np.ndarray, slots: np.ndarray, seen: int | None = None, **values: np.ndarray) -> np.ndarray:
        """Set fields (mean, cov, exists, count, score) of particles ``m`` (P,) at ``slots`` (P,);
        each value one per pair or one for all. With ``seen`` (a maximum score) the pairs were
        observed once more (their EKF update): count + 1 and existence score + 1 up to ``seen``.

        Pairs must be unique. Shared nodes and chunks are copied first (copy-on-write), so only
        these particles change: the nodes by :func:`~.store_kernels.copy_nodes`, the chunks in the
        same pass that writes the values (:func:`~.store_kernels.write_pairs`).

        Returns:
            (P,) the pairs' pool rows after the write (see :meth:`rows`).
        """
        unknown = set(values) - set(_FIELDS)
        if unknown:
            raise ValueError(f"unknown landmark fields {sorted(unknown)}")
        m = np.ascontiguousarray(m, np.int64).ravel()
        slots = np.ascontiguousarray(slots, np.int64).ravel()
        pick = np.empty(m.size, bool)
        g, sub, off, nid = (np.empty(m.size, np.int64) for _ in range(4))
        need = kernels.shared_nodes(self.table, self.node_ref, m, slots, self.chunk, self.fanout,
                                    self._scratch_for(self.table.size), pick, g, sub, off, nid)
        if need:
            self._reserve_nodes(need)
            fl = self._free_nodes
            fl.top, dead = kernels.copy_nodes(
                self.table, self.nodes, self.node_ref, self.refcount, m, g, pick, fl.buf, fl.top, nid
            )
            self._free_dead_nodes(dead)
        target = np.empty(m.size, np.int64)
        need = kernels.plan_chunks(self.nodes, self.refcount, nid, sub, self._scratch_for(self.nodes.size), target)
        self._reserve_chunks(need)
        fl = self._free_chunks
        fl.top -= need
        rows = np.empty(m.size, np.int64)
        freed = kernels.write_pairs(
            self.nodes, self.refcount,
            *(getattr(self, f"pool_{f}").reshape(self.refcount.size, -1) for f in _FIELDS),
            nid, sub, off, target, fl.buf, fl.top,
            *(self._values(f, values.get(f), m.size) for f in _FIELDS), seen is not None, int(seen or 0), rows,
        )
        self._free_chunks.push(np.sort(freed))
        return rows

    def _values(self, name: str, value, n: int) -> np.ndarray:
        """A value for :meth:`write` as the kernel takes it: (n or 1, width) for mean and cov,
        (n or 1,) for the others; (0, ...) when the field is not written."""
        per_slot = getattr(self, f"pool_{name}").shape[2:]
        shape = (-1, math.prod(per_slot)) if per_slot else (-1,)
        dtype = _VALUE_TYPES[name]
        if value is None:
            return np.zeros((0,) + shape[1:], dtype)
        value = np.asarray(value, dtype)
        if value.shape == per_slot:  # one for all
            return np.ascontiguousarray(value.reshape((1,) + shape[1:]))
        if value.shape == (n,) + per_slot:  # one per pair (the filter's writes): no broadcast
            return np.ascontiguousarray(value.reshape(shape))
        return np.ascontiguousarray(np.broadcast_to(value, (n,) + per_slot).reshape(shape))

    def exists_dense(self) -> np.ndarray:
        """(M, size) bool: which particle holds which slot."""
        ex = self.pool_exists[self.chunk_table()].reshape(self.num_particles, -1)
        return ex[:, : self.size]

    def held(self) -> np.ndarray:
        """(size,) bool: the slots some particle holds. Visits each distinct chunk once, not
        each particle's map (particles share most of their chunks)."""
        if self.size == 0:
            return np.zeros(0, bool)
        out = np.zeros((self.table.shape[1] * self.fanout, self.chunk), bool)
        kernels.held_slots(self.table, self.nodes, self.pool_exists, out)
        return out.ravel()[: self.size]

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
        dropped = np.isfinite(self.ref[slots, 0]) & (n == 0)
        self._set_ref(slots, ref)
        if dropped.any():
            self._dindex.stale = True  # a slot left the live set: the descriptor tree is rebuilt

    def set_reference(self, slots: np.ndarray, means: np.ndarray) -> None:
        """Reference positions from values just written: per slot, the mean of ``means`` (P, dim)
        over the pairs that name it (``slots`` (P,)). Cheaper than :meth:`refresh_reference`."""
        if slots.size == 0:
            return
        lo = int(slots.min())  # sums over the slot range: no sort (np.unique) needed
        n, total = kernels.slot_sums(np.ascontiguousarray(slots, np.int64), np.ascontiguousarray(means, float),
                                     lo, int(slots.max()) - lo + 1)
        uniq = np.flatnonzero(n)
        self._set_ref(uniq + lo, total[uniq] / n[uniq, None])

    def _set_ref(self, slots: np.ndarray, ref: np.ndarray) -> None:
        born = slots[~np.isfinite(self.ref[slots, 0]) & np.isfinite(ref[:, 0])]
        self.ref[slots] = ref
        self._dindex.add(born)
        if self._grid is not None:
            self._grid.update(slots, ref)

    def _reset_indexes(self) -> None:
        """Forget the search indexes (rebuilt from ``ref`` and ``descriptor`` when next asked)."""
        self._grid: PositionGrid | None = None
        self._dindex = DescriptorIndex()

    def _live(self) -> np.ndarray:
        return np.flatnonzero(np.isfinite(self.ref[: self.size, 0]))

    def descriptor_candidates(self, desc: np.ndarray, k: int, max_sq_dist: float) -> np.ndarray:
        """Up to ``k`` live slots whose descriptor is within squared distance ``max_sq_dist``
        of each row of ``desc`` (B, D), nearest first: the kd-tree over descriptors of 002
        section III, so association cost grows with log N.

        Returns:
            (B, k) slot indices, -1 where there are fewer.
        """
        return self._dindex.nearest(self.descriptor, self._live(), desc, k,
                                    float(np.sqrt(max_sq_dist)) + 1e-9)

    def grid(self) -> PositionGrid:
        """The position index over the live slots' reference positions."""
        if self._grid is None:
            self._grid = PositionGrid()
            live = self._live()
            self._grid.update(live, self.ref[live])
        return self._grid

    def candidates(self, points: np.ndarray, k: int, radius: float) -> np.ndarray:
        """Up to ``k`` slots whose reference lies within ``radius`` of each point, nearest first.

        Args:
            points: (B, dim) query positions in the map frame [m].

        Returns:
            (B, k) slot indices, -1 where there are fewer candidates.
        """
        return self.grid().nearest(self.ref, points, k, radius)

    def within(self, point: np.ndarray, radius: float) -> np.ndarray:
        """Sorted live slots whose reference lies within ``radius`` of ``point`` (dim,) [m]."""
        return self.grid().within(self.ref, point, radius)

    # ------------------------------------------------------------------ particles
    def copy_rows(self, dst: np.ndarray, src: np.ndarray) -> None:
        """Particles ``dst`` become copies of particles ``src`` (see resampling.copy_plan).

        Only table rows are copied; the nodes and chunks they name are shared until written (see
        :meth:`write`), so later updates of one particle never reach another.
        """
        if dst.size == 0:
            return
        dst = np.ascontiguousarray(dst, np.int64)
        self._free_dead_nodes(kernels.copy_table_rows(self.table, self.node_ref, dst, self.table[src]))

    def dead_fraction(self) -> float:
        """Share of the used slots that no particle holds any more."""
        if self.size == 0:
            return 0.0
        return 1.0 - float(self.held().mean())

    def compact(self) -> np.ndarray:
        """Drop slots no particle holds and renumber the rest densely, keeping sharing: particles
        whose old chunks feeding a new chunk column are the same share the new chunk, and
        particles whose new chunks of a node column are the same share the node.

        Returns:
            (size,) map old slot -> new slot, -1 for dropped slots.
        """
        live = np.flatnonzero(self.held())
        remap = np.full(self.size, -1, np.int64)
        remap[live] = np.arange(live.size)
        old_table = self.chunk_table()
        old_pool = {f: getattr(self, f"pool_{f}") for f in _FIELDS}
        ncols = -(-live.size // self.chunk)
        patterns, owners = [], []
        for j in range(ncols):
            src = live[j * self.chunk : (j + 1) * self.chunk]
            src_cols = np.unique(src // self.chunk)
            pat, owner = unique_rows(old_table[:, src_cols], return_inverse=True)
            patterns.append((src, src_cols, pat))
            owners.append(owner.ravel())
        n_chunks = sum(p[2].shape[0] for p in patterns)
        self._new_pool(n_chunks + 1)
        chunk_table = np.zeros((self.num_particles, ncols), np.int64)
        next_id = 1
        for j, (src, src_cols, pat) in enumerate(patterns):
            ids = np.arange(next_id, next_id + pat.shape[0])
            next_id += pat.shape[0]
            off = src % self.chunk
            col_of = np.searchsorted(src_cols, src // self.chunk)
            for f in _FIELDS:
                getattr(self, f"pool_{f}")[ids, : src.size] = old_pool[f][pat[:, col_of], off[None, :]]
            chunk_table[:, j] = ids[owners[j]]
        self._build_nodes(chunk_table)
        self.descriptor[: live.size] = self.descriptor[live]
        self.ref[: live.size] = self.ref[live]
        for name in SLOT_IDS:
            arr = getattr(self, name)
            arr[: live.size] = arr[live]
        self.ref[live.size : self.size] = np.inf
        self.size = live.size
        self._reset_indexes()
        return remap

    def _new_pool(self, n: int) -> None:
        """An empty pool of ``n`` chunks (their counts and the free list follow from
        :meth:`_build_nodes`)."""
        for f in _FIELDS:
            old = getattr(self, f"pool_{f}")
            setattr(self, f"pool_{f}", np.zeros((n,) + old.shape[1:], old.dtype))
        self.refcount = np.zeros(n, np.int64)

    def _build_nodes(self, chunk_table: np.ndarray) -> None:
        """Table, nodes and reference counts from each particle's chunk per column (M, columns),
        whose ids name chunks of the pool: particles with the same chunks in a node column share
        its node. Pool chunks no column names go to the free list."""
        m, ncols = chunk_table.shape
        groups = -(-ncols // self.fanout)
        padded = np.zeros((m, groups * self.fanout), np.int64)  # unnamed columns: the empty chunk
        padded[:, :ncols] = chunk_table
        rows, owners = [], []
        for g in range(groups):
            pat, owner = unique_rows(padded[:, g * self.fanout : (g + 1) * self.fanout], return_inverse=True)
            rows.append(pat)
            owners.append(owner.ravel())
        total = sum(r.shape[0] for r in rows)
        self.nodes = np.concatenate(rows) if rows else np.zeros((0, self.fanout), np.int64)
        self.node_ref = np.zeros(total, np.int64)
        self.table = np.zeros((m, groups), np.int64)
        first = 0
        for g, (pat, owner) in enumerate(zip(rows, owners)):
            self.table[:, g] = first + owner
            self.node_ref[first : first + pat.shape[0]] = np.bincount(owner, minlength=pat.shape[0])
            first += pat.shape[0]
        self.refcount[:] = np.bincount(self.nodes.ravel(), minlength=self.refcount.size)
        self.refcount[_EMPTY] += 1
        self._refill_free_lists()
        self._grow_nodes(max(total, 1) * 2)

    def _refill_free_lists(self) -> None:
        """The free lists from the reference counts (the lowest free ids are taken first)."""
        self._free_nodes, self._free_chunks = _FreeList(), _FreeList()
        self._free_nodes.push(np.flatnonzero(self.node_ref == 0)[::-1])
        self._free_chunks.push(np.flatnonzero(self.refcount == 0)[::-1])

    # ------------------------------------------------------------------ state
    def state(self) -> dict[str, np.ndarray]:
        """The arrays that make up the store (for a checkpoint), pools and nodes up to the last in
        use: ids stay the same after :meth:`from_state`, and free entries hold nothing ever read."""
        pool = int(np.flatnonzero(self.refcount > 0)[-1]) + 1
        used_nodes = np.flatnonzero(self.node_ref > 0)
        q = int(used_nodes[-1]) + 1 if used_nodes.size else 0
        cut = {"refcount": pool, "nodes": q, "node_ref": q} | {f"pool_{f}": pool for f in _FIELDS}
        return {name: getattr(self, name)[: cut[name]] if name in cut else getattr(self, name)
                for name in STATE_ARRAYS}

    @classmethod
    def from_state(cls, arrays: dict[str, np.ndarray], dim: int, chunk: int, descriptor_dim: int,
                   size: int, fanout: int = 32) -> LandmarkStore:
        """The store :meth:`state` saved. A state without ``nodes`` is the one-level layout (a
        table of pool chunks per chunk column, written before nodes existed): it is regrouped.

        Raises:
            ValueError: arrays that do not make a consistent store (the message says what).
        """
        m = np.asarray(arrays["table"]).shape[0]
        store = cls(m, dim, descriptor_dim, 1, chunk, fanout)
        for name in STATE_ARRAYS:
            if name in arrays:
                setattr(store, name, np.array(arrays[name]))
            elif name in SLOT_IDS:  # written before landmarks had them
                setattr(store, name, np.full(store.descriptor.shape[0], -1, np.int64))
        store.size = int(size)
        if "nodes" not in arrays:
            one_level = np.array(arrays["table"], np.int64)
            if one_level.size and not (0 <= one_level.min() and one_level.max() < store.refcount.size):
                raise ValueError("table names a chunk outside the pool")
            # make room for the empty chunk at 0: shift every id by one
            for f in _FIELDS:
                old = getattr(store, f"pool_{f}")
                setattr(store, f"pool_{f}", np.concatenate([np.zeros((1,) + old.shape[1:], old.dtype), old]))
            store.refcount = np.zeros(store.pool_mean.shape[0], np.int64)
            store._build_nodes(one_level + 1)
        else:
            store._refill_free_lists()
        problems = store.check()
        if problems:
            raise ValueError("; ".join(problems))
        store._reset_indexes()
        return store

    def check(self) -> list[str]:
        """What is inconsistent in the store's arrays (empty: nothing)."""
        dim, chunk = self.dim, self.chunk
        pool, q, cap = self.refcount.shape[0], self.node_ref.shape[0], self.descriptor.shape[0]
        live = self.node_ref > 0
        if self.nodes.shape != (q, self.fanout):
            return ["nodes shape"]
        checks = [
            (self.table.ndim == 2 and self.table.shape[1] * self.fanout * chunk >= self.size,
             "fewer node columns than slots"),
            (self.table.size == 0 or (0 <= self.table.min() and self.table.max() < q), "table names a node outside the nodes"),
            (not live.any() or (0 <= self.nodes[live].min() and self.nodes[live].max() < pool),
             "a node names a chunk outside the pool"),
            (self.pool_mean.shape == (pool, chunk, dim), "pool_mean shape"),
            (self.pool_cov.shape == (pool, chunk, dim, dim), "pool_cov shape"),
            (all(getattr(self, f"pool_{f}").shape == (pool, chunk) for f in ("exists", "count", "score")),
             "pool exists/count/score shape"),
            (self.descriptor.shape == (cap, self.descriptor_dim), "descriptor shape"),
            (self.ref.shape == (cap, dim) and all(getattr(self, a).shape == (cap,) for a in SLOT_IDS),
             "ref/origin/born/maker shape"),
            (0 <= self.size <= cap, "size exceeds capacity"),
        ]
        problems = [what for ok, what in checks if not ok]
        if problems:
            return problems
        if not np.array_equal(np.bincount(self.table.ravel(), minlength=q), self.node_ref):
            problems.append("node_ref != table")
        counted = np.bincount(self.nodes[live].ravel(), minlength=pool)
        counted[_EMPTY] += 1
        if not np.array_equal(counted, self.refcount):
            problems.append("refcount != nodes")
        if pool and (self.pool_exists[_EMPTY].any() or self.pool_count[_EMPTY].any()):
            problems.append("the empty chunk holds values")
        return problems

    def particle_map(self, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Landmarks of particle ``m``: (slots (N,), means (N, dim), covs (N, dim, dim), desc (N, D))."""
        cids = self.nodes[self.table[m]].ravel()[: self.columns]
        slots = np.flatnonzero(self.pool_exists[cids].ravel()[: self.size])
        mean, cov, _, _ = self.gather(np.full(slots.size, m), slots)
        return slots, mean, cov, self.descriptor[slots].copy()
