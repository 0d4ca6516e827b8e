"""The occupancy grid's range_noise in the team profile is the dense obstacle scan's measured
disparity noise: block matching against the rendered depth buffer."""

import numpy as np
import pytest

from mrslam_core.experiments.obstacle_noise import NoiseFit, measure, robust_sigma
from mrslam_core.pipelines.team import TeamConfig


def test_a_robust_sigma_is_the_normal_sigma_and_ignores_outliers():
    e = np.random.default_rng(0).normal(0.1, 0.3, 20000)
    e[:1000] = 50.0  # 5 % gross errors
    assert robust_sigma(e) == pytest.approx(0.3, rel=0.1)  # the std would be 11
    fit = NoiseFit(np.full(e.size, 2.5), e, 27.42, np.array([1.5, 1.5, 3.5, 3.5]), np.array([1.2, 1.6, 3.5, 3.8]),
                   np.array([1.7, 3.1, 3.2, 9.0]))
    assert fit.range_noise == pytest.approx(fit.sigma_d / 27.42)
    assert [b["from_m"] for b in fit.bands()] == [2.0]
    bins = fit.bin_bands()
    assert [(b["from_m"], b["bins"], b["short"], b["long"]) for b in bins] == [(1.0, 2, 0.5, 0.0), (3.0, 2, 0.0, 0.5)]
    assert [b["missed"] for b in bins] == [pytest.approx(1 / 3), 0.5]  # 1 of 3 bins at 1-2 m, 2 of 4 at 3-4 m


def test_the_team_profiles_range_noise_is_the_scans_measured_disparity_noise():
    fit = measure(("office",), views=8)  # 0.0117 1/m; generated worlds 0.0124-0.0141
    assert len(fit.errors) > 50000
    assert 0.2 < fit.sigma_d < 0.5  # block matching at half resolution, in full-resolution pixels
    assert abs(np.median(fit.errors)) < 0.15  # no bias that a σ would hide
    assert TeamConfig().grid.range_noise == pytest.approx(fit.range_noise, rel=0.2), fit.range_noise
    near = fit.bin_bands()[0]  # 1-2 m: the scan's bins are where the rendered depth puts them
    assert near["from_m"] == 1.0 and near["short"] < 0.1 and near["long"] < 0.1, near
