"""The outage-aware MPC of each AGV: problem P3 of the paper (MODEL.md §3, §4 step 1).

For a fixed success probability psi_k the control block is one convex QP per AGV in
z = Delta-mu_k (2 N_p increments):

    min_z  z' G z + H z + M,   G = psi^2 F'Q4F + Q5,  H = 2 psi (C x~ - chi_ref)' Q4 F
    s.t.   |z| <= Delta-a_max                 (increment bound, simple bounds)
           |u[n-1] + T z| <= a_max            (acceleration bound over the horizon)

which is solved as ``min 1/2 z' P z + q' z`` with ``P = 2 G``, ``q = H'``. With a control period
P > 1 that the planners know (MODEL.md §7), move blocking fixes the increments of the slots where no
command goes out to zero (their bounds become [0, 0]), so a command is planned to be held for P slots. The optimal value
``V_k = 1/2 z*' P z* + q' z* + M`` is the expected cost J^_k of MODEL.md §3.

Backends are named as in qpsolvers. ``"daqp"`` (default) and ``"osqp"`` keep one persistent
solver workspace per AGV, updated in place and warm-started from the previous solve;
``"qpsolvers:<name>"`` calls any other qpsolvers backend (stateless). ``"batched"`` solves every
QP of a call at once, also over a leading batch axis of scenarios (``x_aug`` (B, K, 6)): the
batched active-set steps of :class:`lawn_env.qp.PencilQP` settle the problems whose active set
is empty or unchanged since the previous solve, exactly; DAQP solves the rest one by one (the
native ``lawn/Comm-v0`` vector env uses it). A failed or inaccurate
solve falls back to a cold OSQP solve at high accuracy, then to the always-feasible zero
sequence; fallbacks are counted in the returned :class:`MPCSolution`, never raised.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from .dynamics import PredictionModel, command_mask, planning_period

if TYPE_CHECKING:
    from .config import ScenarioConfig

__all__ = ["MPCSolution", "OutageAwareMPC", "SlotData", "BACKENDS"]


@dataclass(frozen=True)
class MPCSolution:
    """Solution of the K control QPs at one slot."""

    increments: np.ndarray  # (K, N_p, 2) Delta-mu_k, m/s^2
    value: np.ndarray  # (K,) V_k = optimal J^_k
    status: np.ndarray  # (K,) 0 primary backend, 1 fallback OSQP, 2 fallback zero sequence (leading axes: batched)
    iterations: np.ndarray  # (K,) solver iterations of the accepted solve
    solve_time_s: float

    @property
    def num_fallbacks(self) -> int:
        return int(np.count_nonzero(self.status))


@dataclass(frozen=True)
class SlotData:
    """The psi-independent data of one slot's K QPs (see :meth:`OutageAwareMPC.prepare`)."""

    residual: np.ndarray  # r = C x~ - chi_ref, (K, 6(N_p+1))
    linear: np.ndarray  # F' Q4 r, (K, 2 N_p)
    constant: np.ndarray  # M = r' Q4 r, (K,)
    lower: np.ndarray  # (K, 4 N_p): increment bounds, then bounds on T z
    upper: np.ndarray


class _DaqpBackend:
    """One persistent ``daqp.Model`` per AGV (dual active set, exact, warm-started)."""

    name = "daqp"

    def __init__(self, num_agvs: int, constraint_matrix: np.ndarray, hessians=None):
        import daqp

        self._daqp = daqp
        self._a = np.array(constraint_matrix, dtype=float, order="C")  # DAQP wants a writable buffer
        self._models = [None] * num_agvs

    def forget(self, rows: np.ndarray) -> None:
        """Drop the workspaces (warm starts) of the problems ``rows``."""
        for i in rows.tolist():
            self._models[i] = None

    def solve(self, k: int, p: np.ndarray, q: np.ndarray, lower: np.ndarray, upper: np.ndarray,
              bounds_changed: bool = True):
        model = self._models[k]
        if model is None:
            model = self._daqp.Model()
            exitflag, _ = model.setup(p, q, self._a, upper, lower)
            self._models[k] = model
            if exitflag < 0:
                self._models[k] = None
                return None, 0, 0.0
        else:
            flag = model.update(H=p, f=q, bupper=upper, blower=lower) if bounds_changed else model.update(H=p, f=q)
            if flag < 0:
                self._models[k] = None
                return None, 0, 0.0
        x, fval, exitflag, info = model.solve()
        if exitflag != 1:
            self._models[k] = None  # start the next solve from a fresh workspace
            return None, info.get("iterations", 0), 0.0
        return x, info["iterations"], fval


class _OsqpBackend:
    """One persistent ``osqp.OSQP`` per AGV, warm-started, polished, tight tolerances."""

    name = "osqp"
    settings = dict(eps_abs=1e-10, eps_rel=1e-10, polishing=True, polish_refine_iter=10,
                    max_iter=50000, verbose=False, warm_starting=True)

    def __init__(self, num_agvs: int, constraint_matrix: np.ndarray, hessians=None):
        import osqp
        from scipy import sparse

        self._osqp = osqp
        n = constraint_matrix.shape[1]
        self._a = sparse.csc_matrix(np.vstack([np.eye(n), constraint_matrix]))
        # column-major order of the upper triangle, matching CSC data of a dense triu matrix
        rows, cols = np.triu_indices(n)
        order = np.lexsort((rows, cols))
        self._triu_csc = (rows[order], cols[order])
        self._sparse = sparse
        self._solvers = [None] * num_agvs

    def solve(self, k, p, q, lower, upper, bounds_changed: bool = True):
        solver = self._solvers[k]
        px = p[self._triu_csc]
        if solver is None:
            solver = self._osqp.OSQP()
            # the full upper-triangle structure, even where entries are zero, so updates fit
            p_csc = self._sparse.csc_matrix((px, self._triu_csc), shape=p.shape)
            solver.setup(P=p_csc, q=q, A=self._a, l=lower, u=upper, **self.settings)
            self._solvers[k] = solver
        else:
            solver.update(Px=px, q=q, l=lower, u=upper)
        res = solver.solve(raise_error=False)
        status = getattr(res.info, "status_val", None)
        ok = (status == 1 or res.info.status == "solved") and np.all(np.isfinite(res.x))
        if not ok:
            self._solvers[k] = None
            return None, int(res.info.iter), 0.0
        x = np.asarray(res.x)
        return x, int(res.info.iter), float(0.5 * x @ p @ x + q @ x)


class _QpsolversBackend:
    """Any qpsolvers backend by name, stateless."""

    def __init__(self, solver: str, num_agvs: int, constraint_matrix: np.ndarray):
        import qpsolvers

        if solver not in qpsolvers.available_solvers:
            raise ValueError(
                f"backend 'qpsolvers:{solver}': solver not installed; available: {', '.join(qpsolvers.available_solvers)}"
            )
        self._qpsolvers = qpsolvers
        self._solver = solver
        self.name = f"qpsolvers:{solver}"
        self._g = np.vstack([constraint_matrix, -constraint_matrix])
        self._n = constraint_matrix.shape[1]

    def solve(self, k, p, q, lower, upper, bounds_changed: bool = True):
        n = self._n
        h = np.concatenate([upper[n:], -lower[n:]])
        x = self._qpsolvers.solve_qp(p, q, G=self._g, h=h, lb=lower[:n], ub=upper[:n], solver=self._solver)
        if x is None or not np.all(np.isfinite(x)):
            return None, 0, 0.0
        x = np.asarray(x)
        return x, 0, float(0.5 * x @ p @ x + q @ x)


class _BatchedBackend:
    """Every problem of a solve at once: :class:`lawn_env.qp.PencilQP` (a primal-dual active-set
    step over the whole stack, warm-started from the previous solve's active sets), exact where
    its KKT check passes; the others by DAQP one by one (warm-started workspaces per problem;
    ``last_settled_share`` is the batched share).

    The increment bounds are tightened by a relative ``TIGHTEN`` (1e-9) inside the batched solve:
    with a_max an integer multiple of Delta-a_max (the default, 2 and 1 m/s^2), a saturating
    sequence of increments meets the acceleration bound exactly and makes the active set
    degenerate, where an active-set step cannot settle. The answers stay feasible for the
    original bounds and their values move by about 1e-9 relative."""

    name = "batched"
    TIGHTEN = 1e-9

    def __init__(self, num_agvs: int, constraint_matrix: np.ndarray, hessians: tuple[np.ndarray, np.ndarray]):
        from .qp import PencilQP

        n = constraint_matrix.shape[1]
        self._n = n
        self.qp = PencilQP(hessians[0], hessians[1], np.vstack([np.eye(n), constraint_matrix]))
        self._a = np.array(constraint_matrix, dtype=float, order="C")
        self._active = None  # (M, 2n) active sets of the previous solve
        self._daqp, self._daqp_size = None, 0  # DAQP workspaces of the problems the batched steps leave
        self.last_settled_share = float("nan")  # of the last solve's problems, settled by the batched steps

    def forget(self, rows: np.ndarray) -> None:
        """Drop the warm starts of the problems ``rows`` (flat indices)."""
        if self._active is not None:
            self._active[rows] = 0
        if self._daqp is not None:
            self._daqp.forget(rows)

    def solve_all(self, s: np.ndarray, q: np.ndarray, lower: np.ndarray, upper: np.ndarray):
        """The M problems at Hessian scalars ``s`` = psi^2: minimizers (M, n), objectives (M,),
        status (M,) int8 and iterations (M,)."""
        n, mm = self._n, s.shape[0]
        lo, up = lower.copy(), upper.copy()
        lo[:, :n] *= 1.0 - self.TIGHTEN
        up[:, :n] *= 1.0 - self.TIGHTEN
        warm = self._active if self._active is not None and self._active.shape[0] == mm else None
        sol = self.qp.solve(s, q, lo, up, active=warm)
        self._active = sol.active
        z, fval = sol.z, sol.objective
        status = np.zeros(mm, dtype=np.int8)
        iterations = sol.iterations.copy()
        unsettled = np.flatnonzero(~sol.converged)
        self.last_settled_share = 1.0 - unsettled.size / max(mm, 1)
        if unsettled.size:
            if self._daqp is None or self._daqp_size != mm:
                self._daqp, self._daqp_size = _DaqpBackend(mm, self._a), mm
            p_all = s[unsettled, None, None] * self.qp.p1 + self.qp.p0
        for j, i in enumerate(unsettled.tolist()):
            p = p_all[j]
            x, its, _ = self._daqp.solve(i, p, q[i], lower[i], upper[i])
            if x is None:  # DAQP failed: a cold OSQP solve, then the zero sequence (counted, status 1 and 2)
                x, its, status[i] = self._fallback(p, q[i], lower[i], upper[i])
            z[i], iterations[i] = x, its
        if unsettled.size:
            zu = z[unsettled]
            fval[unsettled] = 0.5 * np.einsum("ij,ijk,ik->i", zu, p_all, zu) + (q[unsettled] * zu).sum(axis=1)
            self._active[unsettled] = 0  # (DAQP's own active sets as guesses measured slower: weakly active rows)
        return z, fval, status, iterations

    def _fallback(self, p, q, lower, upper):
        x, its, _ = _OsqpBackend(1, self._a).solve(0, p, q, lower, upper)
        if x is not None:
            return x, its, 1
        return np.zeros(self._n), 0, 2


#: The named backends; each is built from (num_agvs, constraint matrix T, Hessians (P0, P1)).
BACKENDS = {"daqp": _DaqpBackend, "osqp": _OsqpBackend, "batched": _BatchedBackend}


def _make_backend(name: str, num_agvs: int, constraint_matrix: np.ndarray, hessians: tuple[np.ndarray, np.ndarray]):
    if name in BACKENDS:
        return BACKENDS[name](num_agvs, constraint_matrix, hessians)
    if name.startswith("qpsolvers:"):
        return _QpsolversBackend(name.split(":", 1)[1], num_agvs, constraint_matrix)
    raise ValueError(f"unknown QP backend {name!r}; valid: {', '.join(BACKENDS)}, or 'qpsolvers:<solver name>'")


class OutageAwareMPC:
    """The K control QPs (P3) with persistent per-AGV solver workspaces.

    ``solve(x_aug, chi_ref, psi)`` returns the optimal increment sequences. Build with
    :meth:`from_config`. The same object serves the Comm-v0 environment and the experts.
    """

    def __init__(self, model: PredictionModel, num_agvs: int, accel_max: float, accel_increment_max: float,
                 backend: str = "daqp", control_period: int = 1):
        if int(control_period) < 1:
            raise ValueError(f"control_period={control_period!r}: must be an integer >= 1")
        self.model = model
        self.control_period = int(control_period)
        self.num_agvs = int(num_agvs)
        self.accel_max = float(accel_max)
        self.accel_increment_max = float(accel_increment_max)
        n = model.num_inputs
        self._n = n
        self._constraint = model.increment_sum
        self._q5_2 = 2.0 * np.asarray(model.q5)
        self._ftq4f_2 = 2.0 * np.asarray(model.ftq4f)
        self.backend = _make_backend(backend, self.num_agvs, self._constraint, self._hessians)
        self._fallback = None  # built lazily: most runs never need it
        # increment bounds per slot phase: zero where move blocking holds the acceleration
        self._boxes = []
        for phase in range(self.control_period):
            allowed = np.repeat(command_mask(phase, model.horizon, self.control_period), 2)
            pos = np.broadcast_to(np.where(allowed, self.accel_increment_max, 0.0), (self.num_agvs, n))
            self._boxes.append((-pos, pos))
        self._box_upper = np.stack([b[1] for b in self._boxes])  # (P, K, n): one row per slot phase (batches)
        self._u_index = np.tile([4, 5], model.horizon)
        self._last_data = None

    @property
    def _hessians(self) -> tuple[np.ndarray, np.ndarray]:
        """(P0, P1) with P = P0 + psi^2 P1: 2 Q5 and 2 F'Q4F."""
        return self._q5_2, self._ftq4f_2

    def __getstate__(self) -> dict:
        """Copies and pickles carry the problem, not the solver workspaces (C objects and modules):
        the copy starts its next solve cold, which changes iteration counts, not solutions."""
        state = self.__dict__.copy()
        state["backend"] = self.backend.name
        state["_fallback"] = None
        state["_last_data"] = None
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self.backend = _make_backend(state["backend"], self.num_agvs, self._constraint, self._hessians)

    @classmethod
    def from_config(cls, config: ScenarioConfig, backend: str = "daqp") -> OutageAwareMPC:
        ctl = config.control
        return cls(PredictionModel.from_config(config), config.num_agvs, ctl.accel_max_mps2,
                   ctl.accel_increment_max_mps2, backend=backend, control_period=planning_period(config))

    def reset(self, which: np.ndarray | None = None) -> None:
        """Drop the solver workspaces (warm starts): the next solve starts cold, so an episode's
        solutions do not depend on the episodes before it. With the ``"batched"`` backend,
        ``which`` (a boolean mask over the leading batch axis of the last solve) drops only those
        scenarios' warm starts."""
        if which is not None and self.backend.name == "batched":
            rows = np.flatnonzero(np.repeat(np.asarray(which, dtype=bool), self.num_agvs))
            self.backend.forget(rows)
            return
        self.backend = _make_backend(self.backend.name, self.num_agvs, self._constraint, self._hessians)
        self._fallback = None
        self._last_data = None

    # ------------------------------------------------------------------ problem data
    def prepare(self, x_aug: np.ndarray, chi_ref: np.ndarray, slot: int | None = None) -> "SlotData":
        """The parts of the K QPs that do not depend on psi (one slot's state and reference).

        ``slot`` (the current slot n) is required when the MPC plans with a control period > 1:
        increments are then allowed only at the slots n + i where a command goes out
        (:func:`lawn_env.dynamics.command_mask`); a batch takes one slot per scenario (B,)."""
        k = self.num_agvs
        if self.control_period == 1:
            neg, pos = self._boxes[0]
        elif slot is None:
            raise ValueError(f"this MPC plans with control_period={self.control_period}: pass slot= (the current slot)")
        elif np.ndim(slot) == 0:
            neg, pos = self._boxes[int(slot) % self.control_period]
        else:  # one slot per scenario of a batch (B,): each scenario's own phase
            pos = self._box_upper[np.asarray(slot) % self.control_period]
            neg = -pos
        window = self.model.horizon + 1
        lead = x_aug.shape[:-2]
        batch_ok = not lead or self.backend.name == "batched"
        if x_aug.shape[-2:] != (k, 6) or chi_ref.shape != lead + (k, window, 6) or not batch_ok:
            raise ValueError(f"x_aug has shape {x_aug.shape} and chi_ref {chi_ref.shape}; this MPC (num_agvs={k}, "
                             f"horizon={self.model.horizon}) needs ({k}, 6) and ({k}, {window}, 6), with a leading "
                             "batch axis (B, ...) only for the 'batched' backend")
        r = self.model.residual(x_aug, chi_ref)
        u_prev = x_aug[..., self._u_index]  # u[n-1] repeated over the horizon, (..., K, 2 N_p)
        shape = u_prev.shape
        return SlotData(
            residual=r,
            linear=r @ self.model.ftq4.T,  # F' Q4 r, so H = 2 psi (F' Q4 r)'
            constant=((r @ self.model.q4) * r).sum(axis=-1),
            lower=np.concatenate([np.broadcast_to(neg, shape), -self.accel_max - u_prev], axis=-1),
            upper=np.concatenate([np.broadcast_to(pos, shape), self.accel_max - u_prev], axis=-1),
        )

    def _objective(self, data: "SlotData", psi: np.ndarray):
        p = (psi * psi)[:, None, None] * self._ftq4f_2 + self._q5_2  # P = 2 G = 2 (psi^2 F'Q4F + Q5)
        q = (2.0 * psi)[:, None] * data.linear
        return p, q

    # ------------------------------------------------------------------ solve
    def solve(self, x_aug: np.ndarray, chi_ref: np.ndarray, psi: npt.ArrayLike, slot: int | None = None) -> MPCSolution:
        """Solve the K QPs at success probabilities ``psi`` (K,) (``slot`` as for :meth:`prepare`)."""
        return self.solve_prepared(self.prepare(x_aug, chi_ref, slot), psi)

    def solve_prepared(self, data: SlotData, psi: npt.ArrayLike) -> MPCSolution:
        """Solve the K QPs of a prepared slot at success probabilities ``psi`` (K,): the AO's
        control block calls this once per iteration with the same ``data`` (the bounds are then
        passed to the workspaces only once)."""
        start = time.perf_counter()
        k = self.num_agvs
        psi = np.asarray(psi, dtype=float)
        if self.backend.name == "batched":
            return self._solve_stack(data, psi, start)
        if psi.shape != (k,):
            psi = np.broadcast_to(psi, (k,))
        p, q = self._objective(data, psi)
        lower, upper = data.lower, data.upper
        bounds_changed = data is not self._last_data
        self._last_data = data
        z = np.empty((k, self._n))
        fval = np.empty(k)
        status = np.zeros(k, dtype=np.int8)
        iterations = np.zeros(k, dtype=np.int64)
        solve = self.backend.solve
        for i in range(k):
            x, its, f = solve(i, p[i], q[i], lower[i], upper[i], bounds_changed)
            if x is None:
                x, its, status[i] = self._fallback_solve(i, p[i], q[i], lower[i], upper[i])
                f = 0.5 * x @ p[i] @ x + q[i] @ x
            if self.control_period > 1:  # the blocked increments exactly zero (solvers return ~1e-14)
                x = np.clip(x, lower[i, : self._n], upper[i, : self._n])
            z[i] = x
            fval[i] = f
            iterations[i] = its
        return MPCSolution(
            increments=z.reshape(k, self.model.horizon, 2),
            value=fval + data.constant,
            status=status,
            iterations=iterations,
            solve_time_s=time.perf_counter() - start,
        )

    def command_stakes(self, data: SlotData) -> np.ndarray:
        """What delivering each AGV's command is worth this slot: ``V_k(0) - V_k(1)`` >= 0, the QP's
        optimal value when the command is sure to be lost minus when it is sure to arrive (any
        leading batch axes, (..., K)). At psi = 0 the increments never act, so zero is optimal
        (feasible, since the simulator keeps |u[n-1]| <= a_max) and ``V_k(0) = r' Q4 r`` is the
        prepared constant; ``V_k(1)`` is one solve."""
        delivered = self.solve_prepared(data, np.ones(data.constant.shape)).value
        return np.maximum(data.constant - delivered, 0.0)

    def _solve_stack(self, data: "SlotData", psi: np.ndarray, start: float) -> MPCSolution:
        """Every QP of the slot (any leading batch axes) in one batched solve."""
        lead = data.constant.shape
        psi = np.broadcast_to(psi, lead)
        n = self._n
        q = (2.0 * psi)[..., None] * data.linear
        z, fval, status, iterations = self.backend.solve_all(
            (psi * psi).reshape(-1), q.reshape(-1, n), data.lower.reshape(-1, 2 * n), data.upper.reshape(-1, 2 * n))
        if self.control_period > 1:  # the blocked increments exactly zero
            z = np.clip(z, data.lower.reshape(-1, 2 * n)[:, :n], data.upper.reshape(-1, 2 * n)[:, :n])
        return MPCSolution(
            increments=z.reshape(lead + (self.model.horizon, 2)),
            value=fval.reshape(lead) + data.constant,
            status=status.reshape(lead),
            iterations=iterations.reshape(lead),
            solve_time_s=time.perf_counter() - start,
        )

    def _fallback_solve(self, i, p, q, lower, upper):
        if self.backend.name != "osqp":
            if self._fallback is None:
                self._fallback = _OsqpBackend(self.num_agvs, self._constraint)
            x, its, _ = self._fallback.solve(i, p, q, lower, upper)
            if x is not None:
                return x, its, 1
        # the zero sequence is feasible whenever |u[n-1]| <= a_max, which the simulator keeps
        return np.zeros(self._n), 0, 2
