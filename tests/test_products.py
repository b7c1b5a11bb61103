"""lawn_env.products: the fixed-order products, solves and eigenproblems every simulated and planned
number goes through, against numpy and scipy (the oracles), and the property they exist for: a row's
result does not depend on the batch it is computed in."""

import numpy as np
import pytest
import scipy.linalg

from lawn_env.dynamics import augmented_matrices, dare
from lawn_env.products import eigh, matmul, solve


@pytest.mark.parametrize(("a_shape", "b_shape"), [((5, 3), (3, 4)), ((2, 4, 3), (3, 2)), ((3,), (3, 2)),
                                                  ((4, 3), (3,)), ((3,), (3,)), ((0, 3), (3, 2))])
def test_matmul_is_numpys_product_with_numpys_shapes(a_shape, b_shape, rng):
    a, b = rng.normal(size=a_shape), rng.normal(size=b_shape)
    out = matmul(a, b)
    assert out.shape == (a @ b).shape
    np.testing.assert_allclose(out, a @ b, rtol=1e-13, atol=1e-13)


def test_a_row_is_the_same_alone_and_in_a_batch(rng):
    a, b = rng.normal(size=(257, 8)), rng.normal(size=(8, 8))
    batched = matmul(a, b)
    for i in (0, 1, 100, 256):
        assert np.array_equal(matmul(a[i], b), batched[i])  # bit for bit, not to rounding
        assert np.array_equal(matmul(a[i : i + 1], b)[0], batched[i])


def test_matmul_names_both_shapes_when_they_do_not_multiply():
    with pytest.raises(ValueError, match=r"shapes \(2, 3\) and \(4, 2\) do not multiply"):
        matmul(np.ones((2, 3)), np.ones((4, 2)))


def test_solve_is_numpys_solve(rng):
    a = rng.normal(size=(6, 6)) + 6 * np.eye(6)
    for b in (rng.normal(size=(6, 3)), rng.normal(size=6)):
        np.testing.assert_allclose(solve(a, b), np.linalg.solve(a, b), rtol=1e-12, atol=1e-12)
    perm = np.eye(3)[[2, 0, 1]]  # a zero leading pivot: partial pivoting finds the others
    np.testing.assert_allclose(solve(perm, np.arange(3.0)), np.linalg.solve(perm, np.arange(3.0)))
    with pytest.raises(ValueError, match=r"a must be \(n, n\)"):
        solve(np.ones((2, 3)), np.ones(2))


@pytest.mark.parametrize("n", [1, 2, 5, 12, 20])
def test_eigh_is_scipys_eigh(n, rng):
    m = rng.normal(size=(n, n))
    m = m @ m.T
    values, vectors = eigh(m)
    np.testing.assert_allclose(values, scipy.linalg.eigh(m, eigvals_only=True), rtol=1e-12, atol=1e-12 * n)
    np.testing.assert_allclose(vectors.T @ vectors, np.eye(n), atol=1e-13)
    np.testing.assert_allclose(vectors.T @ m @ vectors, np.diag(values), atol=1e-11 * np.abs(m).max())
    assert all(v[np.argmax(np.abs(v))] > 0 for v in vectors.T)  # the sign convention
    with pytest.raises(ValueError, match="finite square matrix"):
        eigh(np.full((2, 2), np.nan))


@pytest.mark.parametrize("slot_s", [0.1, 0.5, 2.0])
def test_dare_is_scipys_solution(slot_s):
    a, b = augmented_matrices(slot_s)
    q, r = np.diag([1.0, 1.0, 0.5, 0.5, 0.1, 0.1]), np.diag([2.0, 2.0])
    x = dare(a, b, q, r)
    expected = scipy.linalg.solve_discrete_are(a, b, q, r)
    np.testing.assert_allclose(x, expected, rtol=1e-10, atol=1e-10 * np.abs(expected).max())
    assert np.array_equal(x, x.T)


def test_dare_refuses_an_unstabilizable_system():
    a, b = np.diag([2.0, 0.5]), np.array([[0.0], [1.0]])  # the unstable mode gets no input
    with pytest.raises(ValueError, match="no stabilizing solution"):
        dare(a, b, np.eye(2), np.eye(1))
