"""Closed-form small-matrix algebra against numpy."""

import numpy as np

from mrslam_core.linalg import is_positive_definite, quad_form, sym_inv_det


def _spd(rng, n, k):
    a = rng.standard_normal((k, n, n))
    return a @ np.swapaxes(a, 1, 2) + 0.1 * np.eye(n)


def test_inverse_and_determinant_match_numpy():
    rng = np.random.default_rng(0)
    for n in (2, 3):
        a = _spd(rng, n, 50)
        inv, det = sym_inv_det(a)
        np.testing.assert_allclose(inv, np.linalg.inv(a), rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(det, np.linalg.det(a), rtol=1e-9)
        v = rng.standard_normal((50, n))
        np.testing.assert_allclose(quad_form(v, a), np.einsum("ki,kij,kj->k", v, a, v), rtol=1e-12)


def test_positive_definite_check():
    good = np.eye(3)[None] * 0.1
    bad = np.array([[[1.0, 2, 0], [2, 1, 0], [0, 0, 1]]])
    nan = np.full((1, 3, 3), np.nan)
    assert is_positive_definite(np.concatenate([good, bad, nan])).tolist() == [True, False, False]
