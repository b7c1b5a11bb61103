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

import numba
import numpy as np
import scipy.linalg

__all__ = ["AxisPencils", "solve_stack", "SOLVER_TOL", "SOLVER_MAX_ITER"]

#: Feasibility tolerance of an answer, relative to ``max(1, |bound|)``.
SOLVER_TOL = 1e-10
#: Iterations (working-set changes) after which a problem is handed to the fallback.
SOLVER_MAX_ITER = 100


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
                    ev[:nf], vec[:nf, :nf] = scipy.linalg.eigh(sub1[:nf, :nf], sub0[:nf, :nf])  # raises unless P0 > 0
                w[ph, ax], lam[ph, ax] = vec, np.maximum(ev, 0.0)  # P1 is PSD: clip rounding below zero
                g[ph, ax] = red @ vec
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
        return solve_stack(c(s, dtype=np.float64), c(q, dtype=np.float64), c(lower, dtype=np.float64),
                           c(upper, dtype=np.float64), c(phase, dtype=np.int64), self.free, self.num_free,
                           self.group_end, self.w, self.lam, self.g, self.p0, self.p1, active, float(tol), int(max_iter))


# The compiled functions below name the arrays of one axis problem alike. The scratch arrays are
# allocated once per call of solve_stack and reused by every problem:
#   wv, gv        the pencil of the problem's (phase, axis): W (n, n) and G = A W (m, n), m = 2 n
#   n, nf         padded and free variables: loops run over j < nf; row j is z_j, row n + j the
#                 running sum sum_{i<=j} z_i (padded rows are never read)
#   s             the problem's psi^2; d (n,) = 1 / (1 + s lambda): (s P1 + P0)^-1 = W diag(d) W'
#   qa            (n,) the linear term on the free variables
#   lo, up        (m,) the rows' bounds; tlo, tup how far a row may pass them, tol * max(1, |bound|)
#   z0, az0       the unconstrained minimizer and its row values; zz the current point; y scratch
#   rows, sgn     the working set: its rows and their sides (+1 upper, -1 lower), the first nw entries
#   lmb           their multipliers; lst the set's equality-constrained multipliers
#   member        (m,) int8: which rows are in the set
#   chol, cinv    lower Cholesky factor of the set's dual Hessian M_WW, the inverses of its diagonal
#                 (multiplications, not divisions, in the solves)
#   rhs, col      scratch; col holds L^-1 M_W,r of the row r last offered to the set
# Only solve_stack allocates. The functions it calls are compiled without numba's reference counts
# (_nrt=False, as numba compiles its own allocation-free helpers): they keep no array beyond their
# call, and the counts numba would add for every array argument, on branches its pruning pass cannot
# pair, cost more than the arithmetic of these short loops. They take plain arrays, not named tuples
# of them: a call passes every field of every array it is given, so a tuple's unused arrays would
# cost on every call, and inlining every call instead lengthens the first compilation.
_kernel = numba.njit(cache=True, error_model="numpy", _nrt=False)


@numba.njit(cache=True, error_model="numpy")
def solve_stack(s: np.ndarray, q: np.ndarray, lower: np.ndarray, upper: np.ndarray, phase: np.ndarray,
                free: np.ndarray, num_free: np.ndarray, group_end: np.ndarray, w: np.ndarray, lam: np.ndarray,
                g: np.ndarray, p0: np.ndarray, p1: np.ndarray, active: np.ndarray, tol: float,
                max_iter: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Compiled loop over M AGV problems x 2 axes (see :meth:`AxisPencils.solve`). The reduced
    constraint rows are ``z_j`` (row j) and ``sum_{i<=j} z_i`` (row n + j), j < n_F: their values
    are computed from that structure (:attr:`AxisPencils.a` documents it; the tests check it).
    Returns (z, objective, iterations, settled) as :meth:`AxisPencils.solve`."""
    num = s.shape[0]
    n = w.shape[2]
    m = 2 * n
    z_out = np.zeros((num, 2 * n))
    obj_out = np.zeros(num)
    it_out = np.zeros(num, dtype=np.int64)
    ok_out = np.zeros(num, dtype=np.bool_)
    # scratch, allocated once per call (the names of the notes above)
    qa, d, z0, zz, y = np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    lo, up, tlo, tup, az0 = np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m)
    rows, sgn, lmb, member = np.empty(m, dtype=np.int64), np.empty(m), np.zeros(m), np.zeros(m, dtype=np.int8)
    chol, cinv, lst, rhs, col = np.zeros((m, m)), np.zeros(m), np.empty(m), np.empty(m), np.empty(m)
    for i in range(num):
        ph = phase[i]
        nf = num_free[ph]
        total_it = 0
        good = True
        obj = 0.0
        for ax in range(2):
            wv = w[ph, ax]
            gv = g[ph, ax]
            _reduce_axis(q, lower, upper, free, group_end, i, ph, ax, n, nf, tol, qa, lo, up, tlo, tup)
            _unconstrained_minimizer(wv, lam, ph, ax, s[i], n, nf, qa, d, y, z0, az0)
            nw = _start_set(gv, d, n, nf, lo, up, az0, active, i, ax, rows, sgn, lmb, member, chol, cinv, col)
            nw, it, done = _iterate(wv, gv, d, n, nf, lo, up, tlo, tup, z0, zz, y, az0, rows, sgn, lmb, member,
                                    chol, cinv, lst, rhs, col, nw, max_iter)
            total_it += it
            if not done:
                good = False
                continue
            _refine(wv, gv, d, n, nf, lo, up, tlo, tup, zz, y, az0, rows, sgn, nw, chol, cinv, lst, rhs)
            for t in range(nw):
                active[i, ax, rows[t]] = np.int8(sgn[t])
            obj = _add_objective(p0, p1, ph, ax, s[i], nf, qa, zz, obj)
            if not np.isfinite(obj):  # non-finite data (a caller's NaN or inf): the fallback decides
                good = False
                continue
            for j in range(nf):  # an active increment bound met exactly, not to rounding
                z_out[i, 2 * free[ph, j] + ax] = min(max(zz[j], lo[j]), up[j])
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
def _reduce_axis(q, lower, upper, free, group_end, i, ph, ax, n, nf, tol, qa, lo, up, tlo,
                 tup):  # pragma: no cover - compiled
    """Problem ``i``'s linear term ``qa``, row bounds ``lo``, ``up`` and feasibility thresholds
    ``tlo``, ``tup`` on the free variables of axis ``ax`` (phase ``ph``). The running-sum rows
    between two free increments are one row with the tightest of their bounds."""
    for j in range(nf):
        h = free[ph, j]
        qa[j] = q[i, 2 * h + ax]
        lo[j] = lower[i, 2 * h + ax]
        up[j] = upper[i, 2 * h + ax]
        lrow = -np.inf
        urow = np.inf
        for r in range(h, group_end[ph, j]):
            lrow = max(lrow, lower[i, 2 * n + 2 * r + ax])
            urow = min(urow, upper[i, 2 * n + 2 * r + ax])
        lo[n + j] = lrow
        up[n + j] = urow
    for j in range(nf):  # feasibility thresholds, relative to the bound
        for r in (j, n + j):
            tup[r] = tol * max(1.0, abs(up[r]))
            tlo[r] = tol * max(1.0, abs(lo[r]))


@_kernel
def _unconstrained_minimizer(wv, lam, ph, ax, s, n, nf, qa, d, y, z0, az0):  # pragma: no cover - compiled
    """``d = 1 / (1 + s lambda)``, the unconstrained minimizer ``z0 = -W diag(d) W' q``
    and its row values ``az0`` (the increments and their running sums)."""
    for j in range(nf):
        d[j] = 1.0 / (1.0 + s * lam[ph, ax, j])
    for j in range(nf):
        acc = 0.0
        for k in range(nf):
            acc += wv[k, j] * qa[k]
        y[j] = -acc * d[j]
    run = 0.0
    for k in range(nf):
        acc = 0.0
        for j in range(nf):
            acc += wv[k, j] * y[j]
        z0[k] = acc
        run += acc
        az0[k] = acc
        az0[n + k] = run


@_kernel
def _start_set(gv, d, n, nf, lo, up, az0, active, i, ax, rows, sgn, lmb, member, chol, cinv,
               col):  # pragma: no cover - compiled
    """The first working set: the rows of ``active[i, ax]`` (the problem's previous working set,
    cleared as it is read), then the rows the unconstrained minimizer violates, each taken while
    the set stays linearly independent. All start with zero multipliers: feasible for the dual, so
    any set is a valid start. Returns the set's size."""
    nw = 0
    member[:] = 0
    for r in range(2 * n):
        side = active[i, ax, r]
        if side == 0:
            continue
        active[i, ax, r] = 0
        if r % n >= nf:
            continue
        if _append(gv, d, rows, sgn, nw, r, float(side), chol, cinv, col, nf):
            nw = _push(rows, sgn, lmb, member, nw, r, float(side), 0.0)
    for r in range(2 * n):
        if r % n >= nf or member[r]:
            continue
        side = 0.0
        if az0[r] > up[r]:
            side = 1.0
        elif az0[r] < lo[r]:
            side = -1.0
        if side != 0.0 and _append(gv, d, rows, sgn, nw, r, side, chol, cinv, col, nf):
            nw = _push(rows, sgn, lmb, member, nw, r, side, 0.0)
    return nw


@_kernel
def _iterate(wv, gv, d, n, nf, lo, up, tlo, tup, z0, zz, y, az0, rows, sgn, lmb, member, chol, cinv, lst, rhs, col,
             nw, max_iter):  # pragma: no cover - compiled
    """The dual active-set iterations from a start set of ``nw`` rows: (the final set's size, the
    iterations, whether the problem is solved), a solved problem's point in ``zz``. Unsolved: the
    iteration cap, or a dependent row whose multiplier can grow without limit (inconsistent
    constraints)."""
    it = 0
    while it < max_iter:
        it += 1
        _equality_multipliers(lo, up, az0, rows, sgn, nw, chol, cinv, rhs, lst)
        blocking, step = _first_to_zero(lmb, lst, nw)
        if blocking >= 0 and step == 0.0 and _all_zero(lmb, nw):
            nw = _drop_negative(gv, d, nf, rows, sgn, lmb, member, nw, chol, cinv, lst)
            continue
        if blocking >= 0:  # step towards lst until a multiplier reaches zero, drop it
            for t in range(nw):
                lmb[t] += step * (lst[t] - lmb[t])
            _drop_factor_row(chol, cinv, nw, blocking)
            member[rows[blocking]] = 0
            nw = _remove(rows, sgn, lmb, nw, blocking)
            continue
        for t in range(nw):
            lmb[t] = lst[t]
        add_row, add_side = _most_violated(wv, gv, d, n, nf, lo, up, tlo, tup, z0, zz, y, rows, sgn, lmb, member, nw)
        if add_row < 0:
            return nw, it, True
        member[add_row] = 1
        if _append(gv, d, rows, sgn, nw, add_row, add_side, chol, cinv, col, nf):
            nw = _push(rows, sgn, lmb, member, nw, add_row, add_side, 0.0)
            continue
        exchanged = _exchange_dependent(gv, d, nf, rows, sgn, lmb, member, nw, chol, cinv, col, rhs, add_row, add_side)
        if exchanged < 0:
            return nw, it, False
        nw = exchanged
    return nw, it, False


@_kernel
def _equality_multipliers(lo, up, az0, rows, sgn, nw, chol, cinv, rhs, lst):  # pragma: no cover - compiled
    """The working set's equality-constrained multipliers: ``M_WW lst = -(slack of z0)``."""
    for t in range(nw):
        r = rows[t]
        rhs[t] = (az0[r] - up[r]) if sgn[t] > 0 else (lo[r] - az0[r])
    _chol_solve(chol, cinv, nw, rhs, lst)


@_kernel
def _first_to_zero(lmb, lst, nw):  # pragma: no cover - compiled
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
def _all_zero(values, nw):  # pragma: no cover - compiled
    for t in range(nw):
        if values[t] != 0.0:
            return False
    return True


@_kernel
def _drop_negative(gv, d, nf, rows, sgn, lmb, member, nw, chol, cinv, lst):  # pragma: no cover - compiled
    """At a zero start (multipliers all zero) every row with a negative multiplier ``lst`` can
    leave at once: the multipliers stay zero, feasible for the dual. The factor is rebuilt; returns
    the set's new size."""
    keep = 0
    for t in range(nw):
        if lst[t] < 0.0:
            member[rows[t]] = 0
        else:
            rows[keep] = rows[t]
            sgn[keep] = sgn[t]
            lmb[keep] = 0.0
            keep += 1
    _factor(gv, d, rows, sgn, keep, chol, cinv, nf)
    return keep


@_kernel
def _most_violated(wv, gv, d, n, nf, lo, up, tlo, tup, z0, zz, y, rows, sgn, lmb, member,
                   nw):  # pragma: no cover - compiled
    """The primal point ``zz = z0 - W D G_W' (sgn lmb)`` and the row it violates most beyond the
    row's threshold: (row, side +1 upper / -1 lower); (-1, 0.0) when it violates none."""
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
        acc = z0[k]
        for j in range(nf):
            acc -= wv[k, j] * y[j]
        zz[k] = acc
        run += acc
        for r, v in ((k, acc), (n + k, run)):
            if member[r]:  # held as an equality (to rounding) by the working set
                continue
            over = v - up[r]
            if over > tup[r] and over > worst:
                worst, add_row, add_side = over, r, 1.0
            under = lo[r] - v
            if under > tlo[r] and under > worst:
                worst, add_row, add_side = under, r, -1.0
    return add_row, add_side


@_kernel
def _exchange_dependent(gv, d, nf, rows, sgn, lmb, member, nw, chol, cinv, col, rhs, r,
                        side):  # pragma: no cover - compiled
    """Row ``r`` (side ``side``, already marked in ``member``) depends on the working set's rows
    (``col`` holds ``L^-1 M_W,r``): move along the null direction of the set's rows (z unchanged,
    the new multiplier grows) until a multiplier of the set reaches zero, and exchange that row for
    ``r``. Returns the set's size, or -1 when no multiplier limits the step (the constraints are
    inconsistent)."""
    _chol_solve_l(chol, cinv, nw, col, rhs)  # rhs = M_WW^-1 M_W,r
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
    member[rows[blocking]] = 0
    nw = _remove(rows, sgn, lmb, nw, blocking)
    nw = _push(rows, sgn, lmb, member, nw, r, side, step)
    _factor(gv, d, rows, sgn, nw, chol, cinv, nf)
    return nw


@_kernel
def _refine(wv, gv, d, n, nf, lo, up, tlo, tup, zz, y, az0, rows, sgn, nw, chol, cinv, lst,
            rhs):  # pragma: no cover - compiled
    """One step of iterative refinement of ``zz``: ``z = z0 - (...)`` loses digits to cancellation
    when |z0| >> |z| (small Q2, far from the reference); project z back onto the working set's
    equalities, ``dz = P^-1 A_W' mu`` with ``M_WW mu = (bound - A z)_W``, unless the residual is
    already far below the tolerance. ``az0`` is free once the iterations end: it takes the running
    sums of z."""
    if nw == 0:
        return
    run = 0.0
    for k in range(nf):
        run += zz[k]
        az0[n + k] = run
    off = False
    for t in range(nw):
        r = rows[t]
        v = zz[r] if r < n else az0[r]
        rhs[t] = sgn[t] * ((up[r] if sgn[t] > 0 else lo[r]) - v)
        if abs(rhs[t]) > 0.01 * (tup[r] if sgn[t] > 0 else tlo[r]):
            off = True
    if not off:
        return
    _chol_solve(chol, cinv, nw, rhs, lst)
    for k in range(nf):
        acc = 0.0
        for t in range(nw):
            acc += gv[rows[t], k] * sgn[t] * lst[t]
        y[k] = acc * d[k]
    for k in range(nf):
        acc = 0.0
        for j in range(nf):
            acc += wv[k, j] * y[j]
        zz[k] += acc


@_kernel
def _add_objective(p0, p1, ph, ax, s, nf, qa, zz, obj):  # pragma: no cover - compiled
    """``obj`` plus the axis problem's objective ``1/2 z'(s P1 + P0) z + q'z`` at ``zz``, term by
    term (P0 is diagonal)."""
    p1v = p1[ph, ax]
    for k in range(nf):
        acc = 0.0
        for j in range(nf):
            acc += p1v[k, j] * zz[j]
        obj += zz[k] * (0.5 * (s * acc + p0[ph, ax, k, k] * zz[k]) + qa[k])
    return obj


@numba.njit(cache=True, error_model="numpy", inline="always", _nrt=False)
def _dual_entry(gv, d, r1, s1, r2, s2, nf):  # pragma: no cover - compiled
    acc = 0.0
    for k in range(nf):
        acc += gv[r1, k] * d[k] * gv[r2, k]
    return s1 * s2 * acc


@_kernel
def _append(gv, d, rows, sgn, nw, r, side, chol, cinv, col, nf):  # pragma: no cover - compiled
    """Extend the Cholesky factor by row ``r`` (side ``side``); False (factor unchanged, ``col``
    holding ``L^-1 M_W,r``) when the row is linearly dependent on the working set's rows."""
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
def _push(rows, sgn, lmb, member, nw, r, side, mult):  # pragma: no cover - compiled
    """Row ``r`` (side ``side``, multiplier ``mult``) joins the working set, whose factor the caller
    has extended; returns the set's new size."""
    rows[nw] = r
    sgn[nw] = side
    lmb[nw] = mult
    member[r] = 1
    return nw + 1


@_kernel
def _factor(gv, d, rows, sgn, nw, chol, cinv, nf):  # pragma: no cover - compiled
    """Cholesky factor of the working set's dual Hessian from scratch."""
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
def _drop_factor_row(chol, cinv, nw, t):  # pragma: no cover - compiled
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
def _remove(rows, sgn, lmb, nw, t):  # pragma: no cover - compiled
    for u in range(t, nw - 1):
        rows[u] = rows[u + 1]
        sgn[u] = sgn[u + 1]
        lmb[u] = lmb[u + 1]
    return nw - 1


@_kernel
def _chol_solve(chol, cinv, nw, rhs, out):  # pragma: no cover - compiled
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
def _chol_solve_l(chol, cinv, nw, half, out):  # pragma: no cover - compiled
    """out = L'^-1 half (``half`` = L^-1 b already): the second half of :func:`_chol_solve`."""
    for t in range(nw - 1, -1, -1):
        acc = half[t]
        for u in range(t + 1, nw):
            acc -= chol[u, t] * out[u]
        out[t] = acc * cinv[t]
