"""Weights in log space, effective sample size and low-variance resampling."""

from __future__ import annotations

import numpy as np


def logsumexp(a: np.ndarray) -> float:
    """log Σ exp(a) of a 1-D array, computed as ``scipy.special.logsumexp`` computes it (the
    largest terms kept out of the sum, log1p of the rest), so results are bit for bit scipy's;
    scipy's array-API dispatch costs about 0.2 ms a call, this about 20 µs."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        a_max = a.max()
        top = a == a_max
        m = float(np.count_nonzero(top))
        s = np.sum(np.exp(np.where(top, -np.inf, a) - a_max))
        if s != 0:
            s = s / m
        out = np.log1p(s) + np.log(m) + a_max
        if not np.isfinite(out):  # scipy's fallback for infinite or NaN results
            out = np.log(np.sum(np.exp(a)))
    return float(out)


def normalise_log_weights(log_w: np.ndarray) -> np.ndarray:
    """log w − log Σ exp(log w), (M,). All −inf (every particle impossible) becomes uniform."""
    total = logsumexp(log_w)
    if not np.isfinite(total):
        return np.full(log_w.shape, -np.log(log_w.size))
    return log_w - total


def effective_sample_fraction(log_w: np.ndarray) -> float:
    """Normalised effective sample size (1/Σw²)/M of normalised log weights (M,), in (0, 1]."""
    w = np.exp(log_w)
    return float(1.0 / np.sum(w * w) / log_w.size)


def low_variance_indices(log_w: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Systematic (low-variance) resampling: ancestor index of each new particle, sorted, (M,)."""
    m = log_w.size
    cdf = np.cumsum(np.exp(log_w - logsumexp(log_w)))
    cdf[-1] = 1.0
    u = (rng.random() + np.arange(m)) / m
    return np.searchsorted(cdf, u, side="right").clip(0, m - 1)


def copy_plan(index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Turn ancestor indices (M,) into the fewest row copies: ``rows[dst] = rows[src]``.

    Particles drawn at least once keep their row; each further draw is copied into the row of a
    particle that was not drawn. The resulting population equals ``rows[index]`` up to order.
    """
    m = index.size
    counts = np.bincount(index, minlength=m)
    dst = np.flatnonzero(counts == 0)
    src = np.repeat(np.arange(m), np.maximum(counts - 1, 0))
    return dst, src
