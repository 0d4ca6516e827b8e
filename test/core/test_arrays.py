import numpy as np
import pytest

from mrslam_core.arrays import unique_rows


def test_unique_rows_gives_numpys_rows_first_indices_and_inverse():
    rng = np.random.default_rng(3)
    for _ in range(200):
        a = rng.integers(-4, 4, (int(rng.integers(0, 30)), int(rng.integers(1, 4))))
        want = np.unique(a, axis=0, return_index=True, return_inverse=True)
        got = unique_rows(a, return_index=True, return_inverse=True)
        assert got[0].shape == want[0].shape and (got[0] == want[0]).all()
        assert (got[1] == want[1]).all()
        assert (got[2] == want[2].ravel()).all()
        assert (got[0][got[2]] == a).all()


def test_unique_rows_of_cells():
    cells = np.array([[2, 1], [0, 5], [2, 1], [0, 4]])
    assert unique_rows(cells).tolist() == [[0, 4], [0, 5], [2, 1]]
    assert unique_rows(cells, return_index=True)[1].tolist() == [3, 1, 0]
    assert unique_rows(np.zeros((0, 2), np.int64)).shape == (0, 2)
    with pytest.raises(ValueError, match="2-D"):
        unique_rows(np.arange(3))
