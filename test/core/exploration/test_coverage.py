import numpy as np

from mrslam_core.exploration.coverage import explored_fraction


def test_explored_fraction_counts_known_free_cells_across_resolutions():
    truth = np.zeros((4, 6), bool)  # 0.5 m cells: 2 m × 3 m
    truth[1:3, 1:5] = True  # 8 free cells, x in [0.5, 2.5), y in [0.5, 1.5)
    known = np.zeros((20, 30), bool)  # 0.1 m cells starting at (-0.5, -0.5)
    known[:, :20] = True  # x < 1.5 known
    # free cells with centre x < 1.5: x = 0.75 and 1.25 -> 2 columns × 2 rows = 4 of 8
    assert explored_fraction(known, np.array([-0.5, -0.5]), 0.1, truth, 0.5) == 0.5
    assert explored_fraction(np.zeros((1, 1), bool), np.array([10.0, 10.0]), 0.1, truth, 0.5) == 0.0
