"""Weights in log space, effective sample size and low-variance resampling."""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp


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
