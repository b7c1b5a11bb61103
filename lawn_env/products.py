"""Matrix products and small solves in one fixed order, the same on every machine and for every batch size.

numpy's ``@`` and ``np.dot`` hand float64 products to BLAS, whose kernel is picked at load time by
the CPU (or by ``OPENBLAS_CORETYPE``) and, within one kernel, by the shapes: the same product can
differ in its last bits between two machines, or between one scenario and the same scenario inside a
batch of many. The simulator and the experts are chaotic enough (the paper's AO expert, ``sf``,
``epa``) for such a bit to change an episode's cost in its third digit, so every product that decides
a simulated or planned number goes through :func:`matmul` (Python) or :func:`product_into` (compiled
kernels): each output element is one sum over the inner index in ascending order, no BLAS; and every
small linear system solved per step or per decision through :func:`solve` (Gaussian elimination with
partial pivoting, no LAPACK), and every symmetric eigenproblem that shapes a planner through
:func:`eigh` (cyclic Jacobi rotations). ``tests/test_products.py`` checks them against numpy (the oracle) and
their independence of the batch.
"""

from __future__ import annotations

from typing import cast

import numba
import numpy as np

__all__ = ["matmul", "product_into", "solve", "eigh"]


@numba.njit(cache=True)
def product_into(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover - compiled
    """``out[:] = a @ b`` for 2-D ``a`` (m, n), ``b`` (n, p) and ``out`` (m, p): each element
    ``sum_j a[r, j] * b[j, c]`` summed with ``j`` ascending. Four columns at a time: four independent
    sums in flight (each in its own order, so the same bits as one at a time), not one chain of adds."""
    n, p = a.shape[1], b.shape[1]
    full = p - p % 4
    for r in range(a.shape[0]):
        for c in range(0, full, 4):
            acc0 = acc1 = acc2 = acc3 = 0.0
            for j in range(n):
                x = a[r, j]
                acc0 += x * b[j, c]
                acc1 += x * b[j, c + 1]
                acc2 += x * b[j, c + 2]
                acc3 += x * b[j, c + 3]
            out[r, c], out[r, c + 1], out[r, c + 2], out[r, c + 3] = acc0, acc1, acc2, acc3
        for c in range(full, p):
            acc = 0.0
            for j in range(n):
                acc += a[r, j] * b[j, c]
            out[r, c] = acc


def matmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a @ b`` in float64 by :func:`product_into`, for ``a`` of shape (..., n) (any leading axes,
    or a vector (n,)) and ``b`` of shape (n, p) or (n,), with numpy's result shape: (..., p), (...),
    (p,) or a scalar for two vectors. Raises ``ValueError`` naming both shapes when ``n`` differs."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.ndim == 0 or b.ndim not in (1, 2) or a.shape[-1] != b.shape[0]:
        raise ValueError(f"matmul: shapes {a.shape} and {b.shape} do not multiply (a (..., n), b (n, p) or (n,))")
    columns = b if b.ndim == 2 else b.reshape(b.shape[0], 1)
    rows = a.reshape(-1, a.shape[-1])
    out = np.empty((rows.shape[0], columns.shape[1]))
    product_into(rows, columns, out)
    if a.ndim == 1 and b.ndim == 1:
        # numpy's scalar, as a @ b gives (and types as an array, as numpy's annotations of a @ b do)
        return cast(np.ndarray, np.float64(out[0, 0]))
    product: np.ndarray = out.reshape(a.shape[:-1] + (b.shape[1:] if b.ndim == 2 else ()))
    return product


@numba.njit(cache=True)
def _solve_into(a: np.ndarray, b: np.ndarray) -> None:  # pragma: no cover - compiled
    """Overwrite ``b`` (n, m) with ``a^-1 b`` for ``a`` (n, n), itself overwritten by its factor:
    Gaussian elimination with partial pivoting (the first largest pivot), then back substitution."""
    n, m = a.shape[0], b.shape[1]
    for col in range(n):
        pivot = col
        for r in range(col + 1, n):
            if abs(a[r, col]) > abs(a[pivot, col]):
                pivot = r
        if pivot != col:
            for c in range(n):
                a[col, c], a[pivot, c] = a[pivot, c], a[col, c]
            for c in range(m):
                b[col, c], b[pivot, c] = b[pivot, c], b[col, c]
        for r in range(col + 1, n):
            factor = a[r, col] / a[col, col]
            for c in range(col, n):
                a[r, c] -= factor * a[col, c]
            for c in range(m):
                b[r, c] -= factor * b[col, c]
    for r in range(n - 1, -1, -1):
        for c in range(m):
            acc = b[r, c]
            for j in range(r + 1, n):
                acc -= a[r, j] * b[j, c]
            b[r, c] = acc / a[r, r]


def solve(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.linalg.solve(a, b)`` for a small square ``a`` (n, n) and ``b`` (n, m) or (n,), in one fixed
    order (:func:`_solve_into`). A singular ``a`` gives non-finite entries, not an exception: the
    callers' systems are positive definite by construction."""
    a = np.array(a, dtype=np.float64)  # copies: both are overwritten
    out = np.array(b, dtype=np.float64)
    if a.ndim != 2 or a.shape[0] != a.shape[1] or out.ndim not in (1, 2) or out.shape[0] != a.shape[0]:
        raise ValueError(f"solve: shapes {a.shape} and {out.shape}: a must be (n, n) and b (n, m) or (n,)")
    columns = out if out.ndim == 2 else out[:, None]
    _solve_into(a, columns)
    return out


@numba.njit(cache=True)
def _jacobi(a: np.ndarray, v: np.ndarray, max_sweeps: int) -> bool:  # pragma: no cover - compiled
    """Cyclic Jacobi rotations on the symmetric ``a`` (n, n), in place, until every off-diagonal entry
    is negligible against its diagonal pair; ``v`` (the identity on entry) collects the rotations.
    Returns whether it settled within ``max_sweeps`` sweeps (rows then columns ascending)."""
    n = a.shape[0]
    for _ in range(max_sweeps):
        off = 0.0
        for p in range(n):
            for q in range(p + 1, n):
                off += a[p, q] * a[p, q]
        if off == 0.0:
            return True
        for p in range(n):
            for q in range(p + 1, n):
                apq = a[p, q]
                if apq == 0.0 or abs(apq) <= 1e-300:
                    continue
                if abs(apq) <= 2.2e-16 * 1e-3 * np.sqrt(abs(a[p, p] * a[q, q])):
                    a[p, q] = 0.0
                    a[q, p] = 0.0
                    continue
                theta = (a[q, q] - a[p, p]) / (2.0 * apq)
                t = (1.0 if theta >= 0.0 else -1.0) / (abs(theta) + np.sqrt(theta * theta + 1.0))
                c = 1.0 / np.sqrt(t * t + 1.0)
                sn = t * c
                for k in range(n):  # columns p and q
                    akp, akq = a[k, p], a[k, q]
                    a[k, p] = c * akp - sn * akq
                    a[k, q] = sn * akp + c * akq
                for k in range(n):  # rows p and q
                    apk, aqk = a[p, k], a[q, k]
                    a[p, k] = c * apk - sn * aqk
                    a[q, k] = sn * apk + c * aqk
                a[p, q] = 0.0
                a[q, p] = 0.0
                for k in range(n):
                    vkp, vkq = v[k, p], v[k, q]
                    v[k, p] = c * vkp - sn * vkq
                    v[k, q] = sn * vkp + c * vkq
    return False


def eigh(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``scipy.linalg.eigh(a)`` for a small symmetric ``a`` (n, n) in one fixed order (:func:`_jacobi`):
    (eigenvalues ascending (n,), orthonormal eigenvectors as columns (n, n)), each vector's largest entry
    (the first of equal ones) positive. Raises ``ValueError`` when ``a`` is not square and finite."""
    work = np.array(a, dtype=np.float64)
    if work.ndim != 2 or work.shape[0] != work.shape[1] or not np.all(np.isfinite(work)):
        raise ValueError(f"eigh: a must be a finite square matrix, got shape {work.shape}")
    work = 0.5 * (work + work.T)
    vec = np.eye(work.shape[0])
    if not _jacobi(work, vec, 100):
        raise ValueError("eigh: the Jacobi rotations did not settle in 100 sweeps")
    values = np.diag(work).copy()
    order = np.argsort(values, kind="stable")
    values, vec = values[order], vec[:, order]
    for j in range(vec.shape[1]):
        if vec[int(np.argmax(np.abs(vec[:, j]))), j] < 0.0:
            vec[:, j] = -vec[:, j]
    return values, vec
