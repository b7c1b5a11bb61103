"""The MPC's QPs at compiled speed: one exact dual active-set solver over a stack of problems.

Every control QP of the outage-aware MPC (MODEL.md §3) has the form

    min_z  1/2 z' (psi^2 P1 + P0) z + q' z   s.t.  l <= A z <= u,    A = [I; T]

with ``P1 = 2 F'Q4F``, ``P0 = 2 Q5`` and T the running sum of the increments. The axes decouple
(MODEL.md §3): each AGV's problem in 2 N_p variables is two problems in N_p variables, one per axis,
each with its own pencil ``(P0, P1)``. Move blocking (a control period P > 1 that the planners know,
MODEL.md §7) fixes the increments of the slots where no command goes out to zero; those variables
are eliminated, which leaves a problem of the same shape in the n_F free increments (the running-sum
rows between two command slots are one row, with the tightest of their bounds). So one slot phase
and one axis make one *pencil*, built once (:class:`AxisPencils`), and every problem is a scalar
``s = psi^2``, a linear term and bounds on that pencil.

:func:`solve_stack` solves a stack of such AGV problems in one compiled loop (numba, no Python per
problem, no allocation inside the loop), each by the dual active-set method of Goldfarb & Idnani
(Math. Programming 27, 1983) in the form DAQP uses (Arnström, Bemporad & Axehill, IEEE TAC 67(8),
2022: a primal active-set method on the dual problem, with the singular steps that keep the working
set linearly independent when a dependent constraint is added, as happens when a saturating sequence
meets the acceleration bound exactly, a_max being an integer multiple of Delta-a_max):

* **The pencil's shared factorization.** ``P1 W = P0 W diag(lambda)``, ``W' P0 W = I`` gives
  ``(s P1 + P0)^-1 = W diag(1 / (1 + s lambda)) W'`` for every s, so the unconstrained minimizer
  and the dual Hessian ``A P^-1 A' = G diag(d) G'`` (``G = A W``) cost a few matrix-vector products
  per problem; no per-problem inverse or factorization of P.
* **Warm starts.** A problem starts from its previous working set (kept by the caller as a plain
  int8 array) and the rows its unconstrained minimizer violates, each taken while the set stays
  linearly independent, all with zero multipliers (feasible for the dual, so any start is valid);
  the rows whose equality-constrained multipliers come out negative leave together before the
  first step. Any start gives the same minimizer (the problem is strictly convex); a good one
  saves steps.
* **Cheap steps.** The Cholesky factor of the working set's dual Hessian grows by one row when a
  constraint joins and is downdated in ``O(|W|^2)`` when one leaves; the constraint values come from
  the rows' structure (increments and their running sums), not a matrix product.
* **Exact answers.** A problem ends when its multipliers are non-negative and every constraint holds
  to ``tol`` (relative to the bound): its KKT conditions hold to rounding. A problem that reaches the
  iteration cap or finds the working set infeasible is flagged (``settled`` False) for the caller's
  fallback (DAQP, OSQP, then the zero sequence: :class:`lawn_env.mpc.OutageAwareMPC`).

DAQP stays the test oracle (tests/test_qp.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numba
import numpy as np

from .products import eigh, matmul

__all__ = ["AxisPencils", "solve_stack", "SOLVER_TOL", "SOLVER_MAX_ITER"]

#: Feasibility tolerance of an answer, relative to ``max(1, |bound|)``.
SOLVER_TOL = 1e-10
#: Iterations (working-set changes) after which a problem is handed to the fallback.
SOLVER_MAX_ITER = 100


def _pencil_eigh(p1: np.ndarray, p0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``scipy.linalg.eigh(p1, p0)`` for a diagonal ``p0`` > 0 (2 Q5's block): the eigenpairs of
    ``D^-1/2 P1 D^-1/2`` (:func:`lawn_env.products.eigh`, the same bits on every machine), the vectors
    mapped back by ``D^-1/2`` so that ``V' P0 V = I``; scipy is the tests' oracle."""
    d = np.diag(p0).copy()
    if np.any(~(d > 0.0)) or np.any(p0 != np.diag(d)):
        raise ValueError("AxisPencils: each free block of p0 (2 Q5) must be diagonal and positive")
    root = np.sqrt(d)
    values, vectors = eigh(p1 / np.outer(root, root))
    return values, vectors / root[:, None]


@dataclass(frozen=True, eq=False)
class AxisPencils:
    """The reduced problems of every (slot phase, axis): free variables, constraint rows and the
    pencil factorization. Arrays are indexed ``[phase, axis, ...]`` and padded to ``n = N_p``
    variables and ``m = 2 N_p`` rows (padded variables are decoupled with a unit Hessian, padded
    rows have infinite bounds), so one compiled loop serves every phase."""

    horizon: int
    period: int
    free: np.ndarray  # (P, n) int64: horizon index of reduced variable j (-1: padding)
    num_free: np.ndarray  # (P,) int64
    group_end: np.ndarray  # (P, n) int64: running-sum rows free[j] .. group_end[j] - 1 are reduced row j
    w: np.ndarray  # (P, 2, n, n) generalized eigenvectors, W' P0 W = I
    lam: np.ndarray  # (P, 2, n) generalized eigenvalues (>= 0)
    g: np.ndarray  # (P, 2, m, n) A W
    a: np.ndarray  # (P, 2, m, n) reduced constraint matrix [I; T] (zero rows: padding)
    p0: np.ndarray  # (P, 2, n, n)
    p1: np.ndarray  # (P, 2, n, n)

    @classmethod
    def build(cls, p0: np.ndarray, p1: np.ndarray, horizon: int, masks: list[np.ndarray]) -> AxisPencils:
        """From the full Hessians ``p0``, ``p1`` (2N_p x 2N_p, axes interleaved) and, per slot
        phase, the mask of the horizon's increments that may be non-zero (:func:`command_mask`)."""
        n, per = int(horizon), len(masks)
        m = 2 * n
        full = (2 * n, 2 * n)
        if p0.shape != full or p1.shape != full:
            raise ValueError(f"AxisPencils: p0 {p0.shape} and p1 {p1.shape} must be {full}")
        coupling = np.abs(p0[0::2, 1::2]).max() + np.abs(p1[0::2, 1::2]).max()
        if coupling != 0.0:
            raise ValueError(f"AxisPencils: the x-y blocks of the Hessians are not zero (max {coupling:.3g}); "
                             "the axes decouple only for diagonal Q1 and Q2")
        if np.count_nonzero(p0 - np.diag(np.diag(p0))):
            raise ValueError("AxisPencils: p0 (2 Q5) must be diagonal (Q2 is diagonal)")
        free = np.full((per, n), -1, dtype=np.int64)
        num_free = np.zeros(per, dtype=np.int64)
        group_end = np.zeros((per, n), dtype=np.int64)
        w = np.zeros((per, 2, n, n))
        lam = np.zeros((per, 2, n))
        g = np.zeros((per, 2, m, n))
        a = np.zeros((per, 2, m, n))
        q0 = np.zeros((per, 2, n, n))
        q1 = np.zeros((per, 2, n, n))
        for ph, mask in enumerate(masks):
            idx = np.flatnonzero(np.asarray(mask, dtype=bool))
            nf = idx.size
            free[ph, :nf] = idx
            num_free[ph] = nf
            group_end[ph, :nf] = np.append(idx[1:], n)
            red = np.zeros((m, n))
            red[np.arange(nf), np.arange(nf)] = 1.0
            red[n : n + nf, :nf] = np.tril(np.ones((nf, nf)))
            for ax in range(2):
                # the free block's pencil first; padded variables decoupled with P0 = I, P1 = 0, so
                # W is block diagonal and the kernel's loops run over the nf free variables only
                sub0, sub1 = np.eye(n), np.zeros((n, n))
                block0, block1 = p0[ax::2, ax::2][np.ix_(idx, idx)], p1[ax::2, ax::2][np.ix_(idx, idx)]
                sub0[:nf, :nf], sub1[:nf, :nf] = 0.5 * (block0 + block0.T), 0.5 * (block1 + block1.T)
                vec = np.eye(n)
                ev = np.zeros(n)
                if nf:
                    ev[:nf], vec[:nf, :nf] = _pencil_eigh(sub1[:nf, :nf], sub0[:nf, :nf])
                w[ph, ax], lam[ph, ax] = vec, np.maximum(ev, 0.0)  # P1 is PSD: clip rounding below zero
                g[ph, ax] = matmul(red, vec)
                a[ph, ax] = red
                q0[ph, ax], q1[ph, ax] = sub0, sub1
        for arr in (free, num_free, group_end, w, lam, g, a, q0, q1):
            arr.setflags(write=False)
        return cls(n, per, free, num_free, group_end, w, lam, g, a, q0, q1)

    def solve(self, s: np.ndarray, q: np.ndarray, lower: np.ndarray, upper: np.ndarray, phase: np.ndarray,
              active: np.ndarray, tol: float = SOLVER_TOL,
              max_iter: int = SOLVER_MAX_ITER) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The stack of M AGV problems (full layout: ``q`` (M, 2N_p), ``lower``/``upper`` (M, 4N_p),
        increment bounds then running-sum bounds, axes interleaved; ``s`` (M,) = psi^2; ``phase``
        (M,) int slot phase) from the working sets ``active`` (M, 2, 2N_p) int8, updated in place.
        Returns ``z`` (M, 2N_p), ``objective`` (M,) (``1/2 z'Pz + q'z``), ``iterations`` (M,),
        ``settled`` (M,) bool."""
        c = np.ascontiguousarray  # one argument layout: the solver compiles once, not once per caller's views
        stack = (c(s, dtype=np.float64), c(q, dtype=np.float64), c(lower, dtype=np.float64),
                 c(upper, dtype=np.float64), c(phase, dtype=np.int64))
        solved: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] = solve_stack(stack, self.arrays, active,
                                                                                    float(tol), int(max_iter))
        return solved

    @cached_property
    def arrays(self) -> tuple[np.ndarray, ...]:
        """The :class:`Pencils` fields, as the plain tuple :func:`solve_stack` takes."""
        return (self.free, self.num_free, self.group_end, self.w, self.lam, self.g, self.p0, self.p1)


# The compiled functions below take a few named records (NamedTuples of arrays, which numba passes
# as structs) instead of long positional lists:
#   Stack       the M problems: s (M,) = psi^2, q (M, 2n), lower, upper (M, 4n), phase (M,)
#   Pencils     AxisPencils' arrays: free, num_free, group_end, w, lam, g, p0, p1
#   AxisProblem one axis problem's pencil: w (n, n) and g = A W (m, n) of its (phase, axis),
#               d (n,) = 1 / (1 + s lambda) so that (s P1 + P0)^-1 = W diag(d) W', the padded and
#               free sizes n and nf (loops run over j < nf; row j is z_j, row n + j the running sum
#               sum_{i<=j} z_i; padded rows are never read)
#   Rows        the rows' bounds lo, up (m,) and how far a row may pass them, tlo, tup
#               (tol * max(1, |bound|))
#   Point       qa (n,) the linear term on the free variables, z0 and az0 the unconstrained minimizer
#               and its row values, zz the current point, y scratch
#   WorkingSet  rows, sgn: the set's rows and their sides (+1 upper, -1 lower), the first nw entries;
#               lmb their multipliers, lst the set's equality-constrained multipliers; member (m,)
#               int8: which rows are in the set; chol, cinv: lower Cholesky factor of the set's dual
#               Hessian M_WW and the inverses of its diagonal (multiplications, not divisions, in the
#               solves); rhs, col scratch (col holds L^-1 M_W,r of the row r last offered to the set)
# The scratch is allocated once per call of solve_stack and reused by every problem; only
# solve_stack allocates. Stack and Pencils cross from Python as plain tuples (numba's dispatcher
# types a plain tuple in C, a NamedTuple in Python, about 1 us more per call) and are named on entry.
# The functions solve_stack calls are compiled without numba's reference counts (_nrt=False, as
# numba compiles its own allocation-free helpers): they keep no array beyond their call, and the
# counts numba would add for every array argument cost more than the arithmetic of these short loops.
_kernel = numba.njit(cache=True, error_model="numpy", _nrt=False)


class Stack(NamedTuple):
    s: np.ndarray
    q: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    phase: np.ndarray


class Pencils(NamedTuple):
    free: np.ndarray
    num_free: np.ndarray
    group_end: np.ndarray
    w: np.ndarray
    lam: np.ndarray
    g: np.ndarray
    p0: np.ndarray
    p1: np.ndarray


class AxisProblem(NamedTuple):
    w: np.ndarray
    g: np.ndarray
    d: np.ndarray
    n: int
    nf: int


class Rows(NamedTuple):
    lo: np.ndarray
    up: np.ndarray
    tlo: np.ndarray
    tup: np.ndarray


class Point(NamedTuple):
    qa: np.ndarray
    z0: np.ndarray
    zz: np.ndarray
    y: np.ndarray
    az0: np.ndarray


class WorkingSet(NamedTuple):
    rows: np.ndarray
    sgn: np.ndarray
    lmb: np.ndarray
    member: np.ndarray
    chol: np.ndarray
    cinv: np.ndarray
    lst: np.ndarray
    rhs: np.ndarray
    col: np.ndarray


@numba.njit(cache=True, error_model="numpy")
def solve_stack(stack: tuple[np.ndarray, ...], pencils: tuple[np.ndarray, ...], active: np.ndarray, tol: float,
                max_iter: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Compiled loop over M AGV problems x 2 axes (see :meth:`AxisPencils.solve`): ``stack`` holds
    the :class:`Stack` fields, ``pencils`` the :class:`Pencils` fields. The reduced constraint rows
    are ``z_j`` (row j) and ``sum_{i<=j} z_i`` (row n + j), j < n_F: their values are computed from
    that structure (:attr:`AxisPencils.a` documents it; the tests check it). Returns (z, objective,
    iterations, settled) as :meth:`AxisPencils.solve`."""
    st, pen = Stack(*stack), Pencils(*pencils)
    num = st.s.shape[0]
    n = pen.w.shape[2]
    m = 2 * n
    z_out = np.zeros((num, 2 * n))
    obj_out = np.zeros(num)
    it_out = np.zeros(num, dtype=np.int64)
    ok_out = np.zeros(num, dtype=np.bool_)
    d = np.empty(n)
    bd = Rows(np.empty(m), np.empty(m), np.empty(m), np.empty(m))
    pt = Point(np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(m))
    ws = WorkingSet(np.empty(m, dtype=np.int64), np.empty(m), np.zeros(m), np.zeros(m, dtype=np.int8),
                    np.zeros((m, m)), np.zeros(m), np.empty(m), np.empty(m), np.empty(m))
    for i in range(num):
        ph = st.phase[i]
        nf = pen.num_free[ph]
        total_it = 0
        good = True
        obj = 0.0
        for ax in range(2):
            ap = AxisProblem(pen.w[ph, ax], pen.g[ph, ax], d, n, nf)
            _reduce_axis(st, pen, i, ax, ap, tol, pt, bd)
            _unconstrained_minimizer(ap, pen.lam[ph, ax], st.s[i], pt)
            nw = _start_set(ap, bd, pt, ws, active[i, ax])
            nw, it, done = _iterate(ap, bd, pt, ws, nw, max_iter)
            total_it += it
            if not done:
                good = False
                continue
            _refine(ap, bd, pt, ws, nw)
            if not _within_rows(ap, bd, pt):  # inconsistent rows that rounding let through: the fallback decides
                good = False
                continue
            for t in range(nw):
                active[i, ax, ws.rows[t]] = np.int8(ws.sgn[t])
            obj = _add_objective(pen.p0[ph, ax], pen.p1[ph, ax], st.s[i], nf, pt, obj)
            if not np.isfinite(obj):  # non-finite data (a caller's NaN or inf): the fallback decides
                good = False
                continue
            for j in range(nf):  # an active increment bound met exactly, not to rounding
                z_out[i, 2 * pen.free[ph, j] + ax] = min(max(pt.zz[j], bd.lo[j]), bd.up[j])
        obj_out[i] = obj
        it_out[i] = total_it
        ok_out[i] = good
        if not good:
            for k in range(2 * n):
                z_out[i, k] = 0.0
            for ax in range(2):
                for r in range(m):
                    active[i, ax, r] = 0
    return z_out, obj_out, it_out, ok_out


@_kernel
def _reduce_axis(  # pragma: no cover - compiled
    st: Stack, pen: Pencils, i: int, ax: int, ap: AxisProblem, tol: float, pt: Point, bd: Rows,
) -> None:
    """Problem ``i``'s linear term ``pt.qa``, row bounds ``bd.lo``, ``bd.up`` and feasibility
    thresholds ``bd.tlo``, ``bd.tup`` on the free variables of axis ``ax``. The running-sum rows
    between two free increments are one row with the tightest of their bounds."""
    n, nf, ph = ap.n, ap.nf, st.phase[i]
    q, lower, upper, lo, up = st.q, st.lower, st.upper, bd.lo, bd.up
    for j in range(nf):
        h = pen.free[ph, j]
        pt.qa[j] = q[i, 2 * h + ax]
        lo[j] = lower[i, 2 * h + ax]
        up[j] = upper[i, 2 * h + ax]
        lrow = -np.inf
        urow = np.inf
        for r in range(h, pen.group_end[ph, j]):
            lrow = max(lrow, lower[i, 2 * n + 2 * r + ax])
            urow = min(urow, upper[i, 2 * n + 2 * r + ax])
        lo[n + j] = lrow
        up[n + j] = urow
    for j in range(nf):  # feasibility thresholds, relative to the bound
        for r in (j, n + j):
            bd.tup[r] = tol * max(1.0, abs(up[r]))
            bd.tlo[r] = tol * max(1.0, abs(lo[r]))


@_kernel
def _unconstrained_minimizer(  # pragma: no cover - compiled
    ap: AxisProblem, lam: np.ndarray, s: float, pt: Point,
) -> None:
    """``d = 1 / (1 + s lambda)`` (``lam`` the pencil's eigenvalues), the unconstrained minimizer
    ``z0 = -W diag(d) W' q`` and its row values ``az0`` (the increments and their running sums)."""
    wv, d, n, nf, y = ap.w, ap.d, ap.n, ap.nf, pt.y
    for j in range(nf):
        d[j] = 1.0 / (1.0 + s * lam[j])
    for j in range(nf):
        acc = 0.0
        for k in range(nf):
            acc += wv[k, j] * pt.qa[k]
        y[j] = -acc * d[j]
    run = 0.0
    for k in range(nf):
        acc = 0.0
        for j in range(nf):
            acc += wv[k, j] * y[j]
        pt.z0[k] = acc
        run += acc
        pt.az0[k] = acc
        pt.az0[n + k] = run


@_kernel
def _start_set(  # pragma: no cover - compiled
    ap: AxisProblem, bd: Rows, pt: Point, ws: WorkingSet, previous: np.ndarray,
) -> int:
    """The first working set: the rows of ``previous`` (the problem's previous working set, (m,)
    int8 sides, cleared as it is read), then the rows the unconstrained minimizer violates, each
    taken while the set stays linearly independent. All start with zero multipliers: feasible for
    the dual, so any set is a valid start. Returns the set's size."""
    n, nf = ap.n, ap.nf
    nw = 0
    ws.member[:] = 0
    for r in range(2 * n):
        side = previous[r]
        if side == 0:
            continue
        previous[r] = 0
        if r % n >= nf:
            continue
        if _append(ap, ws, nw, r, float(side)):
            nw = _push(ws, nw, r, float(side), 0.0)
    for r in range(2 * n):
        if r % n >= nf or ws.member[r]:
            continue
        side = 0.0
        if pt.az0[r] > bd.up[r]:
            side = 1.0
        elif pt.az0[r] < bd.lo[r]:
            side = -1.0
        if side != 0.0 and _append(ap, ws, nw, r, side):
            nw = _push(ws, nw, r, side, 0.0)
    return nw


@_kernel
def _iterate(  # pragma: no cover - compiled
    ap: AxisProblem, bd: Rows, pt: Point, ws: WorkingSet, nw: int, max_iter: int,
) -> tuple[int, int, bool]:
    """The dual active-set iterations from a start set of ``nw`` rows: (the final set's size, the
    iterations, whether the problem is solved), a solved problem's point in ``pt.zz``. Unsolved: the
    iteration cap, or a dependent row whose multiplier can grow without limit (inconsistent
    constraints)."""
    lmb, lst = ws.lmb, ws.lst
    it = 0
    while it < max_iter:
        it += 1
        _equality_multipliers(bd, pt, ws, nw)
        blocking, step = _first_to_zero(lmb, lst, nw)
        if blocking >= 0 and step == 0.0 and _all_zero(lmb, nw):
            nw = _drop_negative(ap, ws, nw)
            continue
        if blocking >= 0:  # step towards lst until a multiplier reaches zero, drop it
            for t in range(nw):
                lmb[t] += step * (lst[t] - lmb[t])
            _drop_factor_row(ws.chol, ws.cinv, nw, blocking)
            ws.member[ws.rows[blocking]] = 0
            nw = _remove(ws, nw, blocking)
            continue
        for t in range(nw):
            lmb[t] = lst[t]
        add_row, add_side = _most_violated(ap, bd, pt, ws, nw)
        if add_row < 0:
            return nw, it, True
        ws.member[add_row] = 1
        if _append(ap, ws, nw, add_row, add_side):
            nw = _push(ws, nw, add_row, add_side, 0.0)
            continue
        exchanged = _exchange_dependent(ap, ws, nw, add_row, add_side)
        if exchanged < 0:
            return nw, it, False
        nw = exchanged
    return nw, it, False


@_kernel
def _equality_multipliers(bd: Rows, pt: Point, ws: WorkingSet, nw: int) -> None:  # pragma: no cover - compiled
    """The working set's equality-constrained multipliers: ``M_WW lst = -(slack of z0)``."""
    for t in range(nw):
        r = ws.rows[t]
        ws.rhs[t] = (pt.az0[r] - bd.up[r]) if ws.sgn[t] > 0 else (bd.lo[r] - pt.az0[r])
    _chol_solve(ws.chol, ws.cinv, nw, ws.rhs, ws.lst)


@_kernel
def _first_to_zero(lmb: np.ndarray, lst: np.ndarray, nw: int) -> tuple[int, float]:  # pragma: no cover - compiled
    """The first multiplier to reach zero on the way from ``lmb`` to ``lst``: (its position, the
    fraction of the way); (-1, 1.0) when none does."""
    blocking = -1
    step = 1.0
    for t in range(nw):
        if lst[t] < 0.0:
            frac = lmb[t] / (lmb[t] - lst[t])
            if blocking < 0 or frac < step:
                step = frac
                blocking = t
    return blocking, step


@_kernel
def _all_zero(values: np.ndarray, nw: int) -> bool:  # pragma: no cover - compiled
    for t in range(nw):  # noqa: SIM110 - numba compiles the loop, not all() over a generator
        if values[t] != 0.0:
            return False
    return True


@_kernel
def _drop_negative(ap: AxisProblem, ws: WorkingSet, nw: int) -> int:  # pragma: no cover - compiled
    """At a zero start (multipliers all zero) every row with a negative multiplier ``lst`` can
    leave at once: the multipliers stay zero, feasible for the dual. The factor is rebuilt; returns
    the set's new size."""
    rows, sgn = ws.rows, ws.sgn
    keep = 0
    for t in range(nw):
        if ws.lst[t] < 0.0:
            ws.member[rows[t]] = 0
        else:
            rows[keep] = rows[t]
            sgn[keep] = sgn[t]
            ws.lmb[keep] = 0.0
            keep += 1
    _factor(ap, ws, keep)
    return keep


@_kernel
def _most_violated(  # pragma: no cover - compiled
    ap: AxisProblem, bd: Rows, pt: Point, ws: WorkingSet, nw: int,
) -> tuple[int, float]:
    """The primal point ``zz = z0 - W D G_W' (sgn lmb)`` and the row it violates most beyond the
    row's threshold: (row, side +1 upper / -1 lower); (-1, 0.0) when it violates none."""
    wv, gv, d, n, nf, y = ap.w, ap.g, ap.d, ap.n, ap.nf, pt.y
    rows, sgn, lmb, member = ws.rows, ws.sgn, ws.lmb, ws.member
    for k in range(nf):
        acc = 0.0
        for t in range(nw):
            acc += gv[rows[t], k] * sgn[t] * lmb[t]
        y[k] = acc * d[k]
    worst = 0.0
    add_row = -1
    add_side = 0.0
    run = 0.0
    for k in range(nf):
        acc = pt.z0[k]
        for j in range(nf):
            acc -= wv[k, j] * y[j]
        pt.zz[k] = acc
        run += acc
        for r, v in ((k, acc), (n + k, run)):
            if member[r]:  # held as an equality (to rounding) by the working set
                continue
            over = v - bd.up[r]
            if over > bd.tup[r] and over > worst:
                worst, add_row, add_side = over, r, 1.0
            under = bd.lo[r] - v
            if under > bd.tlo[r] and under > worst:
                worst, add_row, add_side = under, r, -1.0
    return add_row, add_side


@_kernel
def _exchange_dependent(  # pragma: no cover - compiled
    ap: AxisProblem, ws: WorkingSet, nw: int, r: int, side: float,
) -> int:
    """Row ``r`` (side ``side``, already marked in ``member``) depends on the working set's rows
    (``col`` holds ``L^-1 M_W,r``): move along the null direction of the set's rows (z unchanged,
    the new multiplier grows) until a multiplier of the set reaches zero, and exchange that row for
    ``r``. Returns the set's size, or -1 when no multiplier limits the step (the constraints are
    inconsistent)."""
    rhs, lmb = ws.rhs, ws.lmb
    _chol_solve_l(ws.chol, ws.cinv, nw, ws.col, rhs)  # rhs = M_WW^-1 M_W,r
    blocking = -1
    step = 0.0
    for t in range(nw):
        if rhs[t] > 0.0:
            frac = lmb[t] / rhs[t]
            if blocking < 0 or frac < step:
                step = frac
                blocking = t
    if blocking < 0:
        return -1
    for t in range(nw):
        lmb[t] -= step * rhs[t]
    ws.member[ws.rows[blocking]] = 0
    nw = _remove(ws, nw, blocking)
    nw = _push(ws, nw, r, side, step)
    _factor(ap, ws, nw)
    return nw


@_kernel
def _refine(ap: AxisProblem, bd: Rows, pt: Point, ws: WorkingSet, nw: int) -> None:  # pragma: no cover - compiled
    """One step of iterative refinement of ``zz``: ``z = z0 - (...)`` loses digits to cancellation
    when |z0| >> |z| (small Q2, far from the reference); project z back onto the working set's
    equalities, ``dz = P^-1 A_W' mu`` with ``M_WW mu = (bound - A z)_W``, unless the residual is
    already far below the tolerance. ``az0`` is free once the iterations end: it takes the running
    sums of z."""
    if nw == 0:
        return
    n, nf, zz, az0, rows, sgn, rhs, lst = ap.n, ap.nf, pt.zz, pt.az0, ws.rows, ws.sgn, ws.rhs, ws.lst
    run = 0.0
    for k in range(nf):
        run += zz[k]
        az0[n + k] = run
    off = False
    for t in range(nw):
        r = rows[t]
        v = zz[r] if r < n else az0[r]
        rhs[t] = sgn[t] * ((bd.up[r] if sgn[t] > 0 else bd.lo[r]) - v)
        if abs(rhs[t]) > 0.01 * (bd.tup[r] if sgn[t] > 0 else bd.tlo[r]):
            off = True
    if not off:
        return
    _chol_solve(ws.chol, ws.cinv, nw, rhs, lst)
    for k in range(nf):
        acc = 0.0
        for t in range(nw):
            acc += ap.g[rows[t], k] * sgn[t] * lst[t]
        pt.y[k] = acc * ap.d[k]
    for k in range(nf):
        acc = 0.0
        for j in range(nf):
            acc += ap.w[k, j] * pt.y[j]
        zz[k] += acc


@_kernel
def _within_rows(ap: AxisProblem, bd: Rows, pt: Point) -> bool:  # pragma: no cover - compiled
    """Whether the answer ``pt.zz`` meets every row, the working set's included, within ten times the
    row's feasibility threshold: a set that holds two inconsistent rows (an increment bound and a
    running-sum bound of the same increment, |u[n-1]| beyond a_max by more than one increment) can end
    its iterations when rounding makes their dependence look limited; such an answer is not settled."""
    n, nf, zz = ap.n, ap.nf, pt.zz
    run = 0.0
    for k in range(nf):
        run += zz[k]
        for r, v in ((k, zz[k]), (n + k, run)):
            if v - bd.up[r] > 10.0 * bd.tup[r] or bd.lo[r] - v > 10.0 * bd.tlo[r]:
                return False
    return True


@_kernel
def _add_objective(  # pragma: no cover - compiled
    p0: np.ndarray, p1: np.ndarray, s: float, nf: int, pt: Point, obj: float,
) -> float:
    """``obj`` plus the axis problem's objective ``1/2 z'(s P1 + P0) z + q'z`` at ``pt.zz``, term by
    term (``p0``, ``p1`` the pencil's; P0 is diagonal)."""
    zz = pt.zz
    for k in range(nf):
        acc = 0.0
        for j in range(nf):
            acc += p1[k, j] * zz[j]
        obj += zz[k] * (0.5 * (s * acc + p0[k, k] * zz[k]) + pt.qa[k])
    return obj


@numba.njit(cache=True, error_model="numpy", inline="always", _nrt=False)
def _dual_entry(  # pragma: no cover - compiled
    gv: np.ndarray, d: np.ndarray, r1: int, s1: float, r2: int, s2: float, nf: int,
) -> float:
    acc = 0.0
    for k in range(nf):
        acc += gv[r1, k] * d[k] * gv[r2, k]
    return s1 * s2 * acc


@_kernel
def _append(ap: AxisProblem, ws: WorkingSet, nw: int, r: int, side: float) -> bool:  # pragma: no cover - compiled
    """Extend the Cholesky factor by row ``r`` (side ``side``); False (factor unchanged, ``col``
    holding ``L^-1 M_W,r``) when the row is linearly dependent on the working set's rows."""
    gv, d, nf, rows, sgn, chol, cinv, col = ap.g, ap.d, ap.nf, ws.rows, ws.sgn, ws.chol, ws.cinv, ws.col
    for t in range(nw):
        acc = _dual_entry(gv, d, rows[t], sgn[t], r, side, nf)
        for u in range(t):
            acc -= chol[t, u] * col[u]
        col[t] = acc * cinv[t]
    diag = _dual_entry(gv, d, r, side, r, side, nf)
    rest = diag
    for t in range(nw):
        rest -= col[t] * col[t]
    if rest <= 1e-10 * diag:
        return False
    for t in range(nw):
        chol[nw, t] = col[t]
    chol[nw, nw] = np.sqrt(rest)
    cinv[nw] = 1.0 / chol[nw, nw]
    return True


@_kernel
def _push(ws: WorkingSet, nw: int, r: int, side: float, mult: float) -> int:  # pragma: no cover - compiled
    """Row ``r`` (side ``side``, multiplier ``mult``) joins the working set, whose factor the caller
    has extended; returns the set's new size."""
    ws.rows[nw] = r
    ws.sgn[nw] = side
    ws.lmb[nw] = mult
    ws.member[r] = 1
    return nw + 1


@_kernel
def _factor(ap: AxisProblem, ws: WorkingSet, nw: int) -> None:  # pragma: no cover - compiled
    """Cholesky factor of the working set's dual Hessian from scratch."""
    gv, d, nf, rows, sgn, chol, cinv = ap.g, ap.d, ap.nf, ws.rows, ws.sgn, ws.chol, ws.cinv
    for t in range(nw):
        for u in range(t + 1):
            acc = _dual_entry(gv, d, rows[t], sgn[t], rows[u], sgn[u], nf)
            for v in range(u):
                acc -= chol[t, v] * chol[u, v]
            if u == t:
                chol[t, t] = np.sqrt(max(acc, 1e-300))
                cinv[t] = 1.0 / chol[t, t]
            else:
                chol[t, u] = acc * cinv[u]


@_kernel
def _drop_factor_row(chol: np.ndarray, cinv: np.ndarray, nw: int, t: int) -> None:  # pragma: no cover - compiled
    """The Cholesky factor without row and column ``t`` of its matrix, in O(nw^2): the trailing
    block takes a rank-one update with the dropped column (Givens rotations), then moves up."""
    # rank-one update L22 L22' + x x' with x = chol[t+1:nw, t] (overwritten as it goes)
    for k in range(t + 1, nw):
        x_k = chol[k, t]
        lkk = chol[k, k]
        r = np.sqrt(lkk * lkk + x_k * x_k)
        c = r / lkk
        sn = x_k / lkk
        chol[k, k] = r
        cinv[k] = 1.0 / r
        for i in range(k + 1, nw):
            chol[i, k] = (chol[i, k] + sn * chol[i, t]) / c
            chol[i, t] = c * chol[i, t] - sn * chol[i, k]
    for i in range(t, nw - 1):  # move the rows and columns after t up and left by one
        cinv[i] = cinv[i + 1]
        for j in range(t):
            chol[i, j] = chol[i + 1, j]
        for j in range(t, i + 1):
            chol[i, j] = chol[i + 1, j + 1]


@_kernel
def _remove(ws: WorkingSet, nw: int, t: int) -> int:  # pragma: no cover - compiled
    """Entry ``t`` leaves the working set's rows, sides and multipliers; returns the set's new size."""
    rows, sgn, lmb = ws.rows, ws.sgn, ws.lmb
    for u in range(t, nw - 1):
        rows[u] = rows[u + 1]
        sgn[u] = sgn[u + 1]
        lmb[u] = lmb[u + 1]
    return nw - 1


@_kernel
def _chol_solve(  # pragma: no cover - compiled
    chol: np.ndarray, cinv: np.ndarray, nw: int, rhs: np.ndarray, out: np.ndarray,
) -> None:
    """out = (L L')^-1 rhs on the leading nw entries."""
    for t in range(nw):
        acc = rhs[t]
        for u in range(t):
            acc -= chol[t, u] * out[u]
        out[t] = acc * cinv[t]
    for t in range(nw - 1, -1, -1):
        acc = out[t]
        for u in range(t + 1, nw):
            acc -= chol[u, t] * out[u]
        out[t] = acc * cinv[t]


@_kernel
def _chol_solve_l(  # pragma: no cover - compiled
    chol: np.ndarray, cinv: np.ndarray, nw: int, half: np.ndarray, out: np.ndarray,
) -> None:
    """out = L'^-1 half (``half`` = L^-1 b already): the second half of :func:`_chol_solve`."""
    for t in range(nw - 1, -1, -1):
        acc = half[t]
        for u in range(t + 1, nw):
            acc -= chol[u, t] * out[u]
        out[t] = acc * cinv[t]
