"""Log-space weights, effective sample size and systematic resampling."""

import numpy as np
import pytest

from mrslam_core.slam.resampling import effective_sample_fraction, low_variance_indices, normalise_log_weights


def test_normalise_handles_huge_and_impossible_weights():
    lw = normalise_log_weights(np.array([-1e6, -1e6 + np.log(3.0)]))
    np.testing.assert_allclose(np.exp(lw), [0.25, 0.75])
    np.testing.assert_allclose(np.exp(normalise_log_weights(np.full(4, -np.inf))), 0.25)


def test_effective_sample_fraction():
    assert effective_sample_fraction(np.log(np.full(10, 0.1))) == pytest.approx(1.0)
    assert effective_sample_fraction(np.log(np.array([1.0, 1e-300, 1e-300]))) == pytest.approx(1 / 3)


def test_low_variance_counts_follow_weights():
    rng = np.random.default_rng(0)
    w = np.array([0.5, 0.25, 0.125, 0.125])
    idx = low_variance_indices(np.log(w), rng)
    # systematic resampling gives each particle floor(Mw) or ceil(Mw) copies
    counts = np.bincount(idx, minlength=4)
    assert counts[0] == 2 and counts[1] == 1 and counts[2] + counts[3] == 1
    counts = np.bincount(low_variance_indices(np.log(np.full(8, 1 / 8)), rng), minlength=8)
    np.testing.assert_array_equal(counts, np.ones(8))
    many = np.bincount(low_variance_indices(np.log(np.array([0.7, 0.2, 0.1] + [0.0] * 7) + 1e-300), rng), minlength=10)
    assert many[0] == 7 and many[1] == 2 and many[2] == 1
