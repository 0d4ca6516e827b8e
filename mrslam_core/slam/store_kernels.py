"""Compiled kernels of the landmark store (:mod:`mrslam_core.slam.landmarks`): the pool row of
(particle, slot) pairs, the copy-on-write write that gives writers their own nodes and chunks,
resampling's table-row copies, the release of chunk references and the union of the slots some
particle holds.

numpy did these with a dozen fancy-indexing passes over the P pairs of a write (each a temporary of
P elements); here each is one loop. They follow the numpy versions they replaced exactly, down to
which free id goes to which copy, so stores, checkpoints and filter outputs are unchanged:
within a write, the pairs that share one (particle, node column) or (node, chunk column) are
represented by their LAST occurrence, and representatives take free ids from the top of the stack
in the order of those occurrences.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def pool_rows(table, nodes, chunk, fanout, m, slots, out):
    """out[i] = the pool row (chunk · chunk size + offset) of particle m[i] at slot slots[i]."""
    for i in range(m.size):
        col = slots[i] // chunk
        out[i] = nodes[table[m[i], col // fanout], col % fanout] * chunk + slots[i] % chunk


@njit(cache=True)
def pool_rows_outer(table, nodes, chunk, fanout, cols, which, offset, out):
    """out[p, v] = the pool row of particle p at slot v, for every particle p (out (M, V)): one
    table lookup per particle and distinct chunk column ``cols`` (U,); slot v lies in column
    cols[which[v]] at ``offset[v]``."""
    first = np.empty(cols.size, np.int64)
    for p in range(out.shape[0]):
        for u in range(cols.size):
            first[u] = nodes[table[p, cols[u] // fanout], cols[u] % fanout] * chunk
        for v in range(which.size):
            out[p, v] = first[which[v]] + offset[v]


@njit(cache=True)
def slot_sums(slots, values, lo, span):
    """Per slot in [lo, lo + span): how many pairs name it and the sum of their rows of ``values``
    (P, d), added pair by pair as ``np.bincount`` does. Returns (counts (span,), sums (span, d))."""
    count = np.zeros(span, np.int64)
    total = np.zeros((span, values.shape[1]))
    for i in range(slots.size):
        r = slots[i] - lo
        count[r] += 1
        for d in range(values.shape[1]):
            total[r, d] += values[i, d]
    return count, total


@njit(cache=True)
def _representatives(key, scratch, pick):
    """Mark in ``pick`` the last occurrence of each distinct key among the pairs already in
    ``pick``; returns their number. ``scratch`` is −1 on entry and on return."""
    n = 0
    for i in range(key.size - 1, -1, -1):
        if pick[i]:
            if scratch[key[i]] == -1:
                scratch[key[i]] = i
                n += 1
            else:
                pick[i] = False
    for i in range(key.size):
        if pick[i]:
            scratch[key[i]] = -1
    return n


@njit(cache=True)
def shared_nodes(table, node_ref, m, slots, chunk, fanout, scratch, pick, g, sub, off, nid):
    """Where the pairs (particle m, slot) lie and which of them name a shared node: per pair its
    node column ``g``, chunk column ``sub`` in the node, offset ``off`` in the chunk and node
    ``nid`` (the table's); marks one representative per distinct shared (particle, node column)
    in ``pick`` and returns how many new nodes a write needs."""
    width = table.shape[1]
    key = np.empty(m.size, np.int64)
    for i in range(m.size):
        col = slots[i] // chunk
        off[i] = slots[i] % chunk
        g[i] = col // fanout
        sub[i] = col % fanout
        key[i] = m[i] * width + g[i]
        nid[i] = table[m[i], g[i]]
        pick[i] = node_ref[nid[i]] > 1
    return _representatives(key, scratch, pick)


@njit(cache=True)
def copy_nodes(table, nodes, node_ref, refcount, m, g, pick, free, top, out):
    """Give each represented pair a node of its own, a copy of the shared one, taken from the
    free stack ``free[:top]``; every pair's (now private) node goes to ``out``.

    Returns:
        (the new stack top, the old nodes no table entry names any more).
    """
    n = 0
    for i in range(m.size):
        n += pick[i]
    first = top - n
    j = first
    dead = np.empty(n, np.int64)
    nd = 0
    for i in range(m.size):
        if not pick[i]:
            continue
        old = table[m[i], g[i]]
        new = free[j]
        j += 1
        node_ref[new] = 1
        table[m[i], g[i]] = new
        for f in range(nodes.shape[1]):
            nodes[new, f] = nodes[old, f]
            refcount[nodes[new, f]] += 1
        node_ref[old] -= 1
        if node_ref[old] == 0:
            dead[nd] = old
            nd += 1
    for i in range(m.size):
        out[i] = table[m[i], g[i]]
    return first, dead[:nd]


@njit(cache=True)
def plan_chunks(nodes, refcount, nid, sub, scratch, target):
    """Which pairs (private node nid, chunk column sub) name a shared chunk, and which new chunk
    each will get: ``target[i]`` = the rank of its (node, column)'s representative among all
    representatives (the new chunk is ``free[top − n + target[i]]``), −1 where the chunk is
    private already. Returns n, the new chunks the write needs."""
    fanout = nodes.shape[1]
    n = 0
    # backwards: the last occurrence of each shared (node, column) represents it; representatives
    # are counted from the last, and every pair of a shared chunk takes its representative's count
    for i in range(nid.size - 1, -1, -1):
        target[i] = -1
        if refcount[nodes[nid[i], sub[i]]] > 1:
            key = nid[i] * fanout + sub[i]
            if scratch[key] == -1:
                scratch[key] = n
                n += 1
            target[i] = scratch[key]
    for i in range(nid.size):  # counts from the last -> ranks in pair order
        if target[i] >= 0:
            target[i] = n - 1 - target[i]
            scratch[nid[i] * fanout + sub[i]] = -1
    return n


@njit(cache=True)
def write_pairs(nodes, refcount, mean, cov, exists, count, score, nid, sub, off, target, free, first,
                mean_v, cov_v, exists_v, count_v, score_v, seen, max_score, rows):
    """The copy-on-write write in one pass over the pairs: a pair whose chunk is shared first
    copies it (all fields) to its new chunk ``free[first + target[i]]``, then the given values
    go to its slot, while the chunk is in cache.

    Args:
        nodes, refcount: the store's; mean (P, chunk·dim), cov (P, chunk·dim²), exists, count,
            score (P, chunk): the pools as (chunk, values) views.
        nid, sub, off: (n,) each pair's private node, chunk column and offset in the chunk.
        target: (n,) from :func:`plan_chunks`.
        mean_v (n or 1, dim), cov_v (n or 1, dim²), exists_v, count_v, score_v (n or 1,): values
            to write, one row per pair or one for all; an empty array leaves that field as it is.
        seen: each pair was observed once more: count + 1 and score + 1 up to ``max_score`` (in
            place of count_v and score_v).
        rows: (n,) output, the pool row (chunk · chunk size + offset) of each pair.

    Returns:
        the chunks nothing names any more.
    """
    chunk = exists.shape[1]
    dim = mean.shape[1] // chunk
    wc = dim * dim
    freed = np.empty(nid.size, np.int64)
    nf = 0
    for i in range(nid.size):
        cid = nodes[nid[i], sub[i]]
        if target[i] >= 0 and cid != free[first + target[i]]:
            new = free[first + target[i]]
            for a in range(mean.shape[1]):
                mean[new, a] = mean[cid, a]
            for a in range(cov.shape[1]):
                cov[new, a] = cov[cid, a]
            for a in range(chunk):
                exists[new, a] = exists[cid, a]
                count[new, a] = count[cid, a]
                score[new, a] = score[cid, a]
            nodes[nid[i], sub[i]] = new
            refcount[new] = 1
            refcount[cid] -= 1
            if refcount[cid] == 0:
                freed[nf] = cid
                nf += 1
            cid = new
        o = off[i]
        rows[i] = cid * chunk + o
        if mean_v.shape[0]:
            v = i if mean_v.shape[0] > 1 else 0
            for a in range(dim):
                mean[cid, o * dim + a] = mean_v[v, a]
        if cov_v.shape[0]:
            v = i if cov_v.shape[0] > 1 else 0
            for a in range(wc):
                cov[cid, o * wc + a] = cov_v[v, a]
        if exists_v.shape[0]:
            exists[cid, o] = exists_v[i if exists_v.shape[0] > 1 else 0]
        if count_v.shape[0]:
            count[cid, o] = count_v[i if count_v.shape[0] > 1 else 0]
        if score_v.shape[0]:
            score[cid, o] = score_v[i if score_v.shape[0] > 1 else 0]
        if seen:
            count[cid, o] += 1
            score[cid, o] = min(score[cid, o] + 1, max_score)
    return freed[:nf]


@njit(cache=True)
def release(refcount, cid):
    """Drop one reference to each entry of ``cid`` (repeats allowed). Returns the entries left
    with none (each once, in no order)."""
    out = np.empty(cid.size, np.int64)
    n = 0
    for i in range(cid.size):
        refcount[cid[i]] -= 1
        if refcount[cid[i]] == 0:
            out[n] = cid[i]
            n += 1
    k = 0
    for i in range(n):  # a count that went through 0 to below it is not free
        if refcount[out[i]] == 0:
            out[k] = out[i]
            k += 1
    return out[:k]


@njit(cache=True)
def copy_table_rows(table, node_ref, dst, rows):
    """table[dst[i]] = rows[i] (rows: a copy of the source rows, so sources may be among the
    destinations), with the nodes' reference counts: all new references are counted before the
    old ones are dropped, as whole-array counting does. Returns the nodes no entry names any more."""
    for i in range(dst.size):
        for g in range(rows.shape[1]):
            if rows[i, g] != table[dst[i], g]:
                node_ref[rows[i, g]] += 1
    dead = np.empty(dst.size * rows.shape[1], np.int64)
    nd = 0
    for i in range(dst.size):
        for g in range(rows.shape[1]):
            old = table[dst[i], g]
            if rows[i, g] != old:
                node_ref[old] -= 1
                if node_ref[old] == 0:
                    dead[nd] = old
                    nd += 1
                table[dst[i], g] = rows[i, g]
    return dead[:nd]


@njit(cache=True)
def held_slots(table, nodes, exists, out):
    """out[column, offset] |= the existence flags of every chunk some particle's table names:
    each distinct node is visited once (a node lies in one node column), not each particle."""
    seen = np.zeros(nodes.shape[0], np.bool_)
    fanout = nodes.shape[1]
    for g in range(table.shape[1]):
        for p in range(table.shape[0]):
            nid = table[p, g]
            if seen[nid]:
                continue
            seen[nid] = True
            for f in range(fanout):
                cid = nodes[nid, f]
                for o in range(exists.shape[1]):
                    if exists[cid, o]:
                        out[g * fanout + f, o] = True

