"""Many small QPs of one shape solved together: the batched solver of the outage-aware MPC.

The control QPs of every AGV of every scenario share their constraint matrix and differ in
their Hessian only through one scalar (MODEL.md §3: ``P = psi^2 P1 + P0`` with ``P1 = 2 F'Q4F``
and ``P0 = 2 Q5`` positive definite). :class:`PencilQP` solves a stack of M such problems

    min_z  1/2 z' (s_i P1 + P0) z + q_i' z     s.t.  l_i <= A z <= u_i          (i = 1..M)

with numpy calls over the whole stack, no Python loop per problem:

* **One factorization for every Hessian.** The generalized eigendecomposition ``P1 W = P0 W
  diag(lambda)``, ``W' P0 W = I`` (computed once) gives ``(s P1 + P0)^-1 = W diag(1 / (1 + s
  lambda)) W'`` for every s, so each problem's inverse Hessian is a diagonal scaling between two
  shared matrix products.
* **Primal-dual active-set steps** (Hintermüller, Ito & Kunisch, SIAM J. Optim. 13(3), 2002;
  the semismooth Newton method on the KKT conditions). A guess of the active constraints gives
  the multipliers from the reduced dual system ``S_aa y_a = A_a z0 - b_a`` (``S = A P^-1 A'``,
  ``z0`` the unconstrained minimizer), hence ``z``; the guess is then updated from the signs of
  ``y + c (A z - bound)``. When the guess no longer changes, ``(z, y)`` satisfies the KKT
  conditions: the answer is exact up to the linear algebra (the QPs are strictly convex, so it
  is the unique minimizer DAQP finds).
* **Warm starts.** The guess is the previous solve's active set (a scenario's consecutive slots
  usually keep theirs), or the constraints the unconstrained minimizer violates.
* **A bounded number of steps** (``steps``, default 1), then a KKT check (``tol``); the problems
  that fail it come back with ``converged = False`` for the caller to solve otherwise
  (:class:`lawn_env.mpc.OutageAwareMPC` hands them to DAQP). The method converges fast from a
  nearly right guess but can cycle from a poor one: on Comm-v0 rollouts under random actions,
  where many AGVs saturate their acceleration, more steps (and ADMM iterations to find the
  guess, tried as well) cost more time per settled problem than DAQP takes to solve it, so the
  batched part handles the common case (unchanged or empty active sets) and no more.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

__all__ = ["PencilQP", "PencilSolution"]


@dataclass(frozen=True)
class PencilSolution:
    """The solutions of a stack of M problems (:meth:`PencilQP.solve`)."""

    z: np.ndarray  # (M, n) minimizers (the last iterate where not converged)
    objective: np.ndarray  # (M,) 1/2 z'Pz + q'z
    active: np.ndarray  # (M, m) int8: +1 upper bound active, -1 lower, 0 inactive
    iterations: np.ndarray  # (M,) linear solves: 1 when the unconstrained minimizer is feasible
    converged: np.ndarray  # (M,) bool


class PencilQP:
    """A stack of strictly convex QPs with Hessians ``s_i P1 + P0`` (``P1`` positive
    semidefinite, ``P0`` positive definite, both n x n) and constraints ``l_i <= A z <= u_i``
    (``A`` m x n, linearly independent rows of any active set). See the module docstring."""

    def __init__(self, p0: np.ndarray, p1: np.ndarray, a: np.ndarray, steps: int = 1, tol: float = 1e-9):
        p0, p1, a = (np.asarray(x, dtype=float) for x in (p0, p1, a))
        n = p0.shape[0]
        if p0.shape != (n, n) or p1.shape != (n, n) or a.ndim != 2 or a.shape[1] != n:
            raise ValueError(f"PencilQP: p0 {p0.shape}, p1 {p1.shape} and a {a.shape} must be (n, n), (n, n), (m, n)")
        if not (isinstance(steps, (int, np.integer)) and steps >= 0):
            raise ValueError(f"steps={steps!r}: must be an integer >= 0")
        lam, w = scipy.linalg.eigh(0.5 * (p1 + p1.T), 0.5 * (p0 + p0.T))  # raises if p0 is not positive definite
        self.n, self.m = n, a.shape[0]
        self.p0, self.p1, self.a = p0, p1, a
        self.lam = np.maximum(lam, 0.0)  # P1 is PSD: clip rounding below zero
        self.w = w
        self.g = a @ w  # A W: S = A P^-1 A' = G diag(d) G'
        self.g_sq_t = np.ascontiguousarray((self.g * self.g).T)  # for diag(S) = d @ (G^2)'
        self.steps = int(steps)
        self.tol = float(tol)

    def inverse_diagonal(self, s: np.ndarray) -> np.ndarray:
        """d with ``(s P1 + P0)^-1 = W diag(d) W'``, (M, n)."""
        return 1.0 / (1.0 + s[:, None] * self.lam[None, :])

    def solve(self, s: np.ndarray, q: np.ndarray, lower: np.ndarray, upper: np.ndarray,
              active: np.ndarray | None = None) -> PencilSolution:
        """Solve the M problems with Hessian scalars ``s`` (M,), linear terms ``q`` (M, n) and
        bounds ``lower``, ``upper`` (M, m) (``lower == upper`` makes a row an equality), starting
        from the active sets ``active`` (M, m) of a previous solve when given."""
        s = np.asarray(s, dtype=float)
        mm = s.shape[0]
        if s.shape != (mm,) or q.shape != (mm, self.n) or lower.shape != (mm, self.m) or upper.shape != (mm, self.m):
            raise ValueError(f"PencilQP.solve: s {s.shape}, q {q.shape}, lower {lower.shape}, upper {upper.shape}; "
                             f"expected (M,), (M, {self.n}), (M, {self.m}), (M, {self.m})")
        w = self.w
        d = self.inverse_diagonal(s)
        z0 = -((q @ w) * d) @ w.T
        az0 = z0 @ self.a.T
        equality = lower == upper
        if active is None:
            act = np.where(az0 > upper, 1, np.where(az0 < lower, -1, 0)).astype(np.int8)
        else:
            act = np.array(active, dtype=np.int8, copy=True)
        act[equality] = 1
        st = _State(z=z0.copy(), y=np.zeros((mm, self.m)), act=act, iterations=np.ones(mm, dtype=np.int64),
                    converged=~act.any(axis=1) & ((az0 <= upper) & (az0 >= lower)).all(axis=1))
        ctx = (s, q, lower, upper, equality, d, z0, az0)
        self._active_set(ctx, st, np.flatnonzero(~st.converged))
        return self._finish(ctx, st)

    # ------------------------------------------------------------------ the active-set steps
    def _active_set(self, ctx: tuple, st: _State, todo: np.ndarray) -> None:
        """``steps`` primal-dual active-set updates of the problems ``todo`` from their current
        guesses (in place on ``st``; a problem stops once its guess settles)."""
        s, q, lower, upper, equality, d, z0, az0 = ctx
        g, w = self.g, self.w
        for _ in range(self.steps):
            if todo.size == 0:
                break
            st.iterations[todo] += 1
            a_t = st.act[todo]
            d_t = d[todo]
            bound = np.where(a_t > 0, upper[todo], lower[todo])
            count = np.count_nonzero(a_t, axis=1)
            width = int(count.max())
            y_t = np.zeros((todo.size, self.m))
            if width:
                order = np.argsort(a_t == 0, axis=1, kind="stable")[:, :width]  # active rows first
                pad = np.arange(width)[None, :] >= count[:, None]
                ga = g[order]  # (J, width, n)
                sa = (ga * d_t[:, None, :]) @ ga.transpose(0, 2, 1)
                sa[pad] = 0.0
                sa.transpose(0, 2, 1)[pad] = 0.0
                diag = sa.diagonal(axis1=1, axis2=2).copy()
                diag[pad] = 1.0
                reg = 1e-14 * diag.max(axis=1, keepdims=True)  # guards exactly dependent rows
                sa[:, np.arange(width), np.arange(width)] = diag + reg
                rhs = np.take_along_axis(az0[todo] - bound, order, axis=1)
                rhs[pad] = 0.0
                ya = np.linalg.solve(sa, rhs[..., None])[..., 0]
                ya[pad] = 0.0
                np.put_along_axis(y_t, order, ya, axis=1)
                y_t[a_t == 0] = 0.0  # padded slots point at inactive rows
            z_t = z0[todo] - ((y_t @ g) * d_t) @ w.T
            az = z_t @ self.a.T
            c = 1.0 / (d_t @ self.g_sq_t)  # 1 / S_ii: violations in multiplier units
            new = np.where(y_t + c * (az - upper[todo]) > 0, 1, np.where(y_t + c * (az - lower[todo]) < 0, -1, 0))
            new = new.astype(np.int8)
            new[equality[todo]] = 1
            settled = (new == a_t).all(axis=1)
            st.z[todo], st.y[todo], st.act[todo] = z_t, y_t, new
            st.converged[todo[settled]] = True
            todo = todo[~settled]

    # ------------------------------------------------------------------ the answer
    def _finish(self, ctx: tuple, st: _State) -> PencilSolution:
        """The KKT check of every answer (primal feasibility, multiplier signs) and objectives."""
        s, q, lower, upper, equality, d, z0, az0 = ctx
        z, y, act = st.z, st.y, st.act
        az = z @ self.a.T
        span = 1.0 + np.maximum(np.abs(lower), np.abs(upper))
        feasible = ((az - upper <= self.tol * span) & (lower - az <= self.tol * span)).all(axis=1)
        ymax = 1.0 + np.abs(y).max(axis=1, keepdims=True)
        signs = ((act >= 0) | equality | (y <= self.tol * ymax)) & ((act <= 0) | equality | (y >= -self.tol * ymax))
        converged = st.converged & feasible & signs.all(axis=1) & np.isfinite(z).all(axis=1)
        pz = s[:, None] * (z @ self.p1) + z @ self.p0
        objective = 0.5 * (pz * z).sum(axis=1) + (q * z).sum(axis=1)
        return PencilSolution(z=z, objective=objective, active=act, iterations=st.iterations, converged=converged)


@dataclass
class _State:
    z: np.ndarray
    y: np.ndarray
    act: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray
