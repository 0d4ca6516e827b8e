"""Real data: EuRoC V1_01 (still MAV) rectification and track consistency; Middlebury disparity."""

from __future__ import annotations

import numpy as np
import pytest

from mrslam_core.bench.frontend import distinctiveness, euroc_pairs, middlebury_accuracy
from mrslam_core.frontend import FeatureExtractor, Frontend, FrontendConfig, descriptor_distance


def vertical_disparity(left: np.ndarray, right: np.ndarray) -> tuple[int, float]:
    """Median |row difference| [px] of SIFT matches found independently in both images.

    Keypoints of both images, mutual nearest SIFT descriptors, gated only loosely (disparity
    0..80 px, rows within 12 px) so an unrectified pair shows its vertical offset.
    """
    fx = FeatureExtractor(FrontendConfig(detector="sift", descriptor="sift", max_features=800))
    a, b = fx.detect(left, 16), fx.detect(right, 16)
    (da, _), (db, _) = fx.describe(left, a), fx.describe(right, b)
    dist = descriptor_distance(da, db)
    dx = a.xy[:, None, 0] - b.xy[None, :, 0]
    dy = a.xy[:, None, 1] - b.xy[None, :, 1]
    dist = np.where((dx >= 0) & (dx <= 80) & (np.abs(dy) <= 12), dist, np.inf)
    j = np.argmin(dist, axis=1)
    i = np.arange(len(j))
    ok = (np.argmin(dist, axis=0)[j] == i) & (dist[i, j] < 0.3)
    return int(ok.sum()), float(np.median(np.abs(dy[i[ok], j[ok]])))


@pytest.mark.slow
def test_euroc_rectification_removes_vertical_disparity(euroc_dir):
    rig, pairs = euroc_pairs(euroc_dir)
    left, right, _ = pairs[0]
    n_raw, raw = vertical_disparity(left, right)
    n_rect, rect = vertical_disparity(*rig.rectify(left, right))
    assert n_rect >= 100
    assert rect <= 0.5  # measured 0.11 px
    assert raw >= 3.0  # measured 9 px before rectification: the test can tell


@pytest.mark.slow
def test_euroc_tracks_stay_within_their_covariance(euroc_dir):
    """The MAV is still: every point tracked through >= 10 frames keeps its 3D position.

    Per track, the spread of its positions about their mean, in Mahalanobis terms with each
    measurement's predicted covariance: fraction within 3 sigma (chi-square 3 dof at the 3-sigma
    probability 0.9973: 14.16).
    """
    rig, pairs = euroc_pairs(euroc_dir)
    fe = Frontend(rig, FrontendConfig())
    per_track: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}
    n_obs = []
    for left, right, stamp in pairs:
        obs, scan = fe.step(left, right, stamp)
        assert obs is not None and scan is not None
        n_obs.append(len(obs))
        f = fe.last_frame
        for tid, p, c in zip(f.track_ids, f.points, f.cov):
            per_track.setdefault(int(tid), []).append((p, c))
    assert not fe.drops
    assert n_obs[:2] == [0, 0] and min(n_obs[2:]) == fe.cfg.max_observations
    long = [v for v in per_track.values() if len(v) >= 10]
    assert len(long) >= 50
    m2 = []
    for track in long:
        p = np.array([x for x, _ in track])
        c = np.array([x for _, x in track])
        r = p - p.mean(axis=0)
        m2.append(np.einsum("ni,nij,nj->n", r, np.linalg.inv(c), r))
    within = float(np.mean(np.concatenate(m2) <= 14.16))
    assert within >= 0.9


@pytest.mark.slow
@pytest.mark.parametrize("detector", ["harris", "orb", "sift"])
def test_middlebury_matches_within_one_pixel(detector):
    r = middlebury_accuracy(detector)
    assert r["with_truth"] >= 100
    assert r["within_1px"] >= 0.9  # measured 95.9 / 96.2 / 97.0 %


@pytest.mark.slow
def test_usurf_distinctiveness_on_known_homography(euroc_dir):
    """Harris + U-SURF, EuRoC left image vs its warp by a known homography (002 Table V style)."""
    rig, pairs = euroc_pairs(euroc_dir)
    left, right = rig.rectify(pairs[0][0], pairs[0][1])
    r = distinctiveness(left, FrontendConfig())
    rows = {row["E0"]: row for row in r["rows"]}
    assert r["keypoints"] >= 80
    assert rows[0.5]["correct_fraction"] >= 0.8  # measured 0.82 (Harris + SIFT: 0.99)
    assert rows[0.5]["matches"] >= 0.9 * r["keypoints"]
