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
* **Warm starts.** A problem starts from a given working set (its previous solve's, kept by the
  caller as a plain int8 array), its rows taken while they stay linearly independent; an empty
  set is the cold start. Any start gives the same minimizer (the problem is strictly convex).
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
SOLVER_MAX_ITER = 60


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
                sub0 = np.eye(n)
                sub1 = np.zeros((n, n))
                block0, block1 = p0[ax::2, ax::2], p1[ax::2, ax::2]
                sub0[:nf, :nf] = block0[np.ix_(idx, idx)]
                sub1[:nf, :nf] = block1[np.ix_(idx, idx)]
                sub0, sub1 = 0.5 * (sub0 + sub0.T), 0.5 * (sub1 + sub1.T)
                ev, vec = scipy.linalg.eigh(sub1, sub0)  # raises if P0 is not positive definite
                w[ph, ax], lam[ph, ax] = vec, np.maximum(ev, 0.0)  # P1 is PSD: clip rounding below zero
                g[ph, ax] = red @ vec
                a[ph, ax] = red
                q0[ph, ax], q1[ph, ax] = sub0, sub1
        for arr in (free, num_free, group_end, w, lam, g, a, q0, q1):
            arr.setflags(write=False)
        return cls(n, per, free, num_free, group_end, w, lam, g, a, q0, q1)

    def solve(self, s: np.ndarray, q: np.ndarray, lower: np.ndarray, upper: np.ndarray, phase: np.ndarray,
              active: np.ndarray, tol: float = SOLVER_TOL, max_iter: int = SOLVER_MAX_ITER):
        """The stack of M AGV problems (full layout: ``q`` (M, 2N_p), ``lower``/``upper`` (M, 4N_p),
        increment bounds then running-sum bounds, axes interleaved; ``s`` (M,) = psi^2; ``phase``
        (M,) int slot phase) from the working sets ``active`` (M, 2, 2N_p) int8, updated in place.
        Returns ``z`` (M, 2N_p), ``objective`` (M,) (``1/2 z'Pz + q'z``), ``iterations`` (M,),
        ``settled`` (M,) bool."""
        mm = s.shape[0]
        z = np.zeros((mm, 2 * self.horizon))
        objective = np.zeros(mm)
        iterations = np.zeros(mm, dtype=np.int64)
        settled = np.zeros(mm, dtype=np.bool_)
        solve_stack(s, q, lower, upper, phase, self.free, self.num_free, self.group_end, self.w, self.lam,
                    self.g, self.a, self.p0, self.p1, active, z, objective, iterations, settled, tol, max_iter)
        return z, objective, iterations, settled


@numba.njit(cache=True)
def solve_stack(s, q, lower, upper, phase, free, num_free, group_end, w, lam, g, a, p0, p1, active,
                z_out, obj_out, it_out, ok_out, tol, max_iter):  # pragma: no cover - compiled
    """Compiled loop over M AGV problems x 2 axes (see :meth:`AxisPencils.solve`)."""
    num = s.shape[0]
    n = w.shape[2]
    m = 2 * n
    # scratch, allocated once per call
    qa = np.empty(n)
    lo = np.empty(m)
    up = np.empty(m)
    d = np.empty(n)
    z0 = np.empty(n)
    zz = np.empty(n)
    y = np.empty(n)
    az = np.empty(m)
    az0 = np.empty(m)
    rows = np.empty(m, dtype=np.int64)  # working set: constraint rows ...
    sgn = np.empty(m)  # ... and their sides (+1 upper, -1 lower)
    lmb = np.zeros(m)  # multipliers of the working set
    lst = np.empty(m)  # the working set's equality-constrained multipliers
    rhs = np.empty(m)
    col = np.empty(m)
    chol = np.zeros((m, m))  # lower Cholesky factor of the working set's dual Hessian
    for i in range(num):
        ph = phase[i]
        nf = num_free[ph]
        total_it = 0
        good = True
        obj = 0.0
        for ax in range(2):
            # ---------------------------------------------------------- reduced data of this axis
            for j in range(n):
                if j < nf:
                    h = free[ph, j]
                    qa[j] = q[i, 2 * h + ax]
                    lo[j] = lower[i, 2 * h + ax]
                    up[j] = upper[i, 2 * h + ax]
                    lrow = -np.inf
                    urow = np.inf
                    for r in range(h, group_end[ph, j]):
                        lv = lower[i, 2 * n + 2 * r + ax]
                        uv = upper[i, 2 * n + 2 * r + ax]
                        if lv > lrow:
                            lrow = lv
                        if uv < urow:
                            urow = uv
                    lo[n + j] = lrow
                    up[n + j] = urow
                else:
                    qa[j] = 0.0
                    lo[j] = -np.inf
                    up[j] = np.inf
                    lo[n + j] = -np.inf
                    up[n + j] = np.inf
            wv = w[ph, ax]
            gv = g[ph, ax]
            av = a[ph, ax]
            for j in range(n):
                d[j] = 1.0 / (1.0 + s[i] * lam[ph, ax, j])
            # unconstrained minimizer z0 = -W D W' q
            for j in range(n):
                acc = 0.0
                for k in range(n):
                    acc += wv[k, j] * qa[k]
                y[j] = -acc * d[j]
            for k in range(n):
                acc = 0.0
                for j in range(n):
                    acc += wv[k, j] * y[j]
                z0[k] = acc
            for r in range(m):
                acc = 0.0
                for k in range(n):
                    acc += av[r, k] * z0[k]
                az0[r] = acc
            # ---------------------------------------------------------- warm start: independent rows of the guess
            nw = 0
            for r in range(m):
                side = active[i, ax, r]
                if side == 0:
                    continue
                if (side > 0 and not np.isfinite(up[r])) or (side < 0 and not np.isfinite(lo[r])):
                    active[i, ax, r] = 0
                    continue
                if _append(gv, d, rows, sgn, nw, r, float(side), chol, col, n):
                    rows[nw] = r
                    sgn[nw] = float(side)
                    lmb[nw] = 0.0
                    nw += 1
                active[i, ax, r] = 0
            # ---------------------------------------------------------- the dual active-set iterations
            it = 0
            done = False
            while it < max_iter:
                it += 1
                # equality-constrained multipliers on the working set: M_WW lst = -(slack of z0)
                for t in range(nw):
                    r = rows[t]
                    if sgn[t] > 0:
                        rhs[t] = -(up[r] - az0[r])
                    else:
                        rhs[t] = -(az0[r] - lo[r])
                _chol_solve(chol, nw, rhs, lst)
                blocking = -1
                step = 1.0
                for t in range(nw):
                    if lst[t] < 0.0:
                        frac = lmb[t] / (lmb[t] - lst[t])
                        if blocking < 0 or frac < step:
                            step = frac
                            blocking = t
                if blocking >= 0:  # step towards lst until a multiplier reaches zero, drop it
                    for t in range(nw):
                        lmb[t] += step * (lst[t] - lmb[t])
                    nw = _remove(rows, sgn, lmb, nw, blocking)
                    _factor(gv, d, rows, sgn, nw, chol, n)
                    continue
                for t in range(nw):
                    lmb[t] = lst[t]
                # primal point z = z0 - W D G_W' (sgn lmb) and the most violated constraint
                for k in range(n):
                    acc = 0.0
                    for t in range(nw):
                        acc += gv[rows[t], k] * sgn[t] * lmb[t]
                    y[k] = acc * d[k]
                for k in range(n):
                    acc = z0[k]
                    for j in range(n):
                        acc -= wv[k, j] * y[j]
                    zz[k] = acc
                worst = 0.0
                add_row = -1
                add_side = 0.0
                for r in range(m):
                    acc = 0.0
                    for k in range(n):
                        acc += av[r, k] * zz[k]
                    az[r] = acc
                    if np.isfinite(up[r]):
                        v = (acc - up[r]) / max(1.0, abs(up[r]))
                        if v > tol and v > worst:
                            worst, add_row, add_side = v, r, 1.0
                    if np.isfinite(lo[r]):
                        v = (lo[r] - acc) / max(1.0, abs(lo[r]))
                        if v > tol and v > worst:
                            worst, add_row, add_side = v, r, -1.0
                if add_row < 0:
                    done = True
                    break
                if _append(gv, d, rows, sgn, nw, add_row, add_side, chol, col, n):
                    rows[nw] = add_row
                    sgn[nw] = add_side
                    lmb[nw] = 0.0
                    nw += 1
                    continue
                # the new row depends on the working set: move along the null direction of the
                # working set's rows (z unchanged, the new multiplier grows) until one reaches zero
                _chol_solve_l(chol, nw, col, rhs)  # col held L^-1 M_W,new; rhs = M_WW^-1 M_W,new
                blocking = -1
                step = 0.0
                for t in range(nw):
                    if rhs[t] > 0.0:
                        frac = lmb[t] / rhs[t]
                        if blocking < 0 or frac < step:
                            step = frac
                            blocking = t
                if blocking < 0:  # no multiplier limits the step: the constraints are inconsistent
                    break
                for t in range(nw):
                    lmb[t] -= step * rhs[t]
                nw = _remove(rows, sgn, lmb, nw, blocking)
                rows[nw] = add_row
                sgn[nw] = add_side
                lmb[nw] = step
                nw += 1
                _factor(gv, d, rows, sgn, nw, chol, n)
            total_it += it
            if not done:
                good = False
                continue
            for t in range(nw):
                active[i, ax, rows[t]] = np.int8(sgn[t])
            pz = 0.0
            for k in range(n):
                acc = 0.0
                for j in range(n):
                    acc += (s[i] * p1[ph, ax, k, j] + p0[ph, ax, k, j]) * zz[j]
                pz += zz[k] * (0.5 * acc + qa[k])
            obj += pz
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


@numba.njit(cache=True, inline="always")
def _dual_entry(gv, d, r1, s1, r2, s2, n):  # pragma: no cover - compiled
    acc = 0.0
    for k in range(n):
        acc += gv[r1, k] * d[k] * gv[r2, k]
    return s1 * s2 * acc


@numba.njit(cache=True)
def _append(gv, d, rows, sgn, nw, r, side, chol, col, n):  # pragma: no cover - compiled
    """Extend the Cholesky factor by row ``r`` (side ``side``); False (factor unchanged, ``col``
    holding ``L^-1 M_W,r``) when the row is linearly dependent on the working set's rows."""
    for t in range(nw):
        acc = _dual_entry(gv, d, rows[t], sgn[t], r, side, n)
        for u in range(t):
            acc -= chol[t, u] * col[u]
        col[t] = acc / chol[t, t]
    diag = _dual_entry(gv, d, r, side, r, side, n)
    rest = diag
    for t in range(nw):
        rest -= col[t] * col[t]
    if rest <= 1e-10 * diag:
        return False
    for t in range(nw):
        chol[nw, t] = col[t]
    chol[nw, nw] = np.sqrt(rest)
    return True


@numba.njit(cache=True)
def _factor(gv, d, rows, sgn, nw, chol, n):  # pragma: no cover - compiled
    """Cholesky factor of the working set's dual Hessian from scratch."""
    for t in range(nw):
        for u in range(t + 1):
            acc = _dual_entry(gv, d, rows[t], sgn[t], rows[u], sgn[u], n)
            for v in range(u):
                acc -= chol[t, v] * chol[u, v]
            if u == t:
                chol[t, t] = np.sqrt(max(acc, 1e-300))
            else:
                chol[t, u] = acc / chol[u, u]


@numba.njit(cache=True)
def _remove(rows, sgn, lmb, nw, t):  # pragma: no cover - compiled
    for u in range(t, nw - 1):
        rows[u] = rows[u + 1]
        sgn[u] = sgn[u + 1]
        lmb[u] = lmb[u + 1]
    return nw - 1


@numba.njit(cache=True)
def _chol_solve(chol, nw, rhs, out):  # pragma: no cover - compiled
    """out = (L L')^-1 rhs on the leading nw entries."""
    for t in range(nw):
        acc = rhs[t]
        for u in range(t):
            acc -= chol[t, u] * out[u]
        out[t] = acc / chol[t, t]
    for t in range(nw - 1, -1, -1):
        acc = out[t]
        for u in range(t + 1, nw):
            acc -= chol[u, t] * out[u]
        out[t] = acc / chol[t, t]


@numba.njit(cache=True)
def _chol_solve_l(chol, nw, half, out):  # pragma: no cover - compiled
    """out = L'^-1 half (``half`` = L^-1 b already): the second half of :func:`_chol_solve`."""
    for t in range(nw - 1, -1, -1):
        acc = half[t]
        for u in range(t + 1, nw):
            acc -= chol[u, t] * out[u]
        out[t] = acc / chol[t, t]
