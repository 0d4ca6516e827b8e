"""Array helpers numpy lacks in a form the nodes can rely on."""

from __future__ import annotations

import numpy as np


def unique_rows(a: np.ndarray, return_index: bool = False, return_inverse: bool = False):
    """Unique rows of a 2-D array (N, K), in lexicographic order (first column first).

    The same answer as ``np.unique(a, axis=0, ...)``, computed with a stable ``lexsort`` on the
    columns instead of numpy's structured view, whose comparison raised ``TypeError: Cannot
    compare structured arrays unless they have a common dtype`` for int64 cells in an explore
    node at the end of a demo run (numpy 2.4.6); neither random inputs nor a SIGINT during the
    call reproduced it in isolation.

    Returns:
        unique rows (U, K); with ``return_index`` also (U,) the first row of each in ``a``; with
        ``return_inverse`` also (N,) the unique row of each row of ``a``.
    """
    a = np.asarray(a)
    if a.ndim != 2:
        raise ValueError(f"unique_rows takes a 2-D array, got shape {a.shape}")
    n = a.shape[0]
    if a.shape[1] == 0:
        order = np.arange(n)
    else:
        order = np.lexsort(a.T[::-1])
    rows = a[order]
    first = np.ones(n, bool)
    if n > 1:
        first[1:] = (rows[1:] != rows[:-1]).any(axis=1)
    out = [rows[first]]
    if return_index:
        out.append(order[first])
    if return_inverse:
        inverse = np.empty(n, np.intp)
        inverse[order] = np.cumsum(first) - 1
        out.append(inverse)
    return out[0] if len(out) == 1 else tuple(out)
