"""Globally consistent alignment of four maps on a loop (004 section 3.1).

Four maps around a 20 × 20 m square, each seeing the landmarks within 7 m of its corner (so each
overlaps its two neighbours, not the opposite map), 20 % of each map's descriptors swapped
(wrong matches), σ = 5 cm per coordinate. Map frames have known world poses.
"""

import numpy as np
import pytest

from mrslam_core.fusion.config import FusionConfig
from mrslam_core.fusion.multimap import align_maps, compose_chain
from mrslam_core.fusion.synthetic import make_world, observe_map
from mrslam_core.geometry.se2 import between, inverse, wrap_angle

FRAMES = np.array([[5, 5, 0.0], [15, 4, 1.0], [16, 15, 2.5], [4, 16, -1.8]])
CORNERS = np.array([[5, 5], [15, 5], [15, 15], [5, 15]], float)


def loop_maps(seed: int, corners=CORNERS):
    rng = np.random.default_rng(seed)
    world = make_world(rng, 400, (20.0, 20.0))
    maps = []
    for c, f in zip(corners, FRAMES):
        rows = np.flatnonzero(np.linalg.norm(world.points[:, :2] - c, axis=1) < 7.0)
        maps.append(observe_map(rng, world, rows, f, 0.05, swap=rng.choice(rows.size, rows.size // 5, replace=False)))
    return maps


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_loop_closes_and_poses_are_accurate(seed):
    maps = loop_maps(seed)
    res = align_maps(maps, FusionConfig(seed=seed))
    pw = res.pairwise
    assert {k for k, a in pw.items() if a.accepted} == {(0, 1), (1, 2), (2, 3), (0, 3)}
    # the pairwise RANSAC transforms alone do not compose to the identity around the loop …
    ransac_loop = compose_chain([pw[(0, 1)].transform, pw[(1, 2)].transform, pw[(2, 3)].transform,
                                 inverse(pw[(0, 3)].transform)])
    assert np.hypot(*ransac_loop[:2]) > 0.02
    # … the optimised ones do (004 eq. 2), whichever way round
    np.testing.assert_allclose(res.loop([0, 1, 2, 3]), 0.0, atol=1e-9)
    np.testing.assert_allclose(res.loop([3, 1, 0, 2]), 0.0, atol=1e-9)
    assert res.cost_final < res.cost_initial
    truth = between(FRAMES[0], FRAMES)
    pos = np.linalg.norm(res.poses[:, :2] - truth[:, :2], axis=1)
    ang = np.degrees(np.abs(wrap_angle(res.poses[:, 2] - truth[:, 2])))
    pos0 = np.linalg.norm(res.initial[:, :2] - truth[:, :2], axis=1)
    assert pos.max() < 0.08 and ang.max() < 0.8, (pos, ang)
    assert pos.mean() < pos0.mean(), (pos, pos0)
    np.testing.assert_allclose(res.relative(1, 3), between(res.poses[1], res.poses[3]))


def test_map_without_overlap_stays_unaligned():
    corners = CORNERS.copy()
    corners[2] = [60.0, 60.0]  # map 2 sees nothing of the others' area (nor anything at all)
    maps = loop_maps(5, corners)
    res = align_maps(maps, FusionConfig())
    assert res.aligned.tolist() == [True, True, False, True]
    assert np.isnan(res.poses[2]).all() and np.isfinite(res.poses[[0, 1, 3]]).all()
    assert "do not overlap" in res.pairwise[(1, 2)].reason
