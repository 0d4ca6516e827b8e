"""Assignment correctness on hand-made costs: ML greedy + conflict rule, and Hungarian with
"new landmark" columns (001 III-C)."""

import numpy as np

from mrslam_core.slam.association import associate_hungarian, associate_ml, resolve_conflicts

INF = np.inf


def test_ml_takes_cheapest_candidate_and_resolves_conflicts():
    # 2 observations, 2 candidate columns each; pairs: (b0,c0)->slot 5, (b0,c1)->slot 7,
    # (b1,c0)->slot 5
    vb = np.array([0, 0, 1])
    vc = np.array([0, 1, 0])
    vslots = np.array([5, 7, 5])
    cost = np.array([[0.1, 0.3, 0.05]])  # both want slot 5; observation 1 is cheaper
    pair = associate_ml(cost, vb, vc, 2, 2)
    assert pair.tolist() == [[0, 2]]
    pair, dropped = resolve_conflicts(pair, vslots, cost)
    assert pair.tolist() == [[-1, 2]] and dropped == 1


def test_ml_infeasible_is_new():
    pair = associate_ml(np.array([[INF]]), np.array([0]), np.array([0]), 1, 1)
    assert pair.tolist() == [[-1]]


def test_hungarian_prefers_joint_optimum_over_greedy():
    # obs 0 likes slot A slightly more than B; obs 1 can only be A. Greedy would give A to obs 0
    # and make obs 1 new; the joint optimum gives B to obs 0 and A to obs 1.
    vb = np.array([0, 0, 1])
    vslots = np.array([10, 11, 10])
    log_lik = np.array([[-1.0, -1.2, -1.0]])
    pair = associate_hungarian(log_lik, vb, vslots, np.array([-20.0, -20.0]))
    assert pair.tolist() == [[1, 2]]


def test_hungarian_more_measurements_than_landmarks():
    vb = np.array([0, 1, 2])
    vslots = np.array([3, 3, 3])
    log_lik = np.array([[-5.0, -1.0, -3.0], [-INF, -INF, -INF]])
    pair = associate_hungarian(log_lik, vb, vslots, np.full(3, -8.0))
    assert pair[0].tolist() == [-1, 1, -1]  # one landmark: the best observation takes it
    assert pair[1].tolist() == [-1, -1, -1]  # nothing feasible: all new


def test_hungarian_new_column_beats_poor_match():
    pair = associate_hungarian(np.array([[-30.0]]), np.array([0]), np.array([4]), np.array([-10.0]))
    assert pair.tolist() == [[-1]]
