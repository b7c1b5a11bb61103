"""The outage-aware MPC of each AGV: problem P3 of the paper (MODEL.md §3, §4 step 1).

For a fixed success probability psi_k the control block is one convex QP per AGV in
z = Delta-mu_k (2 N_p increments)::

    min_z  z' G z + H z + M,   G = psi^2 F'Q4F + Q5,  H = 2 psi (C x~ - chi_ref)' Q4 F
    s.t.   |z| <= Delta-a_max                 (increment bound, simple bounds)
           |u[n-1] + T z| <= a_max            (acceleration bound over the horizon)

which is solved as ``min 1/2 z' P z + q' z`` with ``P = 2 G``, ``q = H'``. With a control period
P > 1 that the planners know (MODEL.md §7), move blocking fixes the increments of the slots where no
command goes out to zero (their bounds become [0, 0]), so a command is planned to be held for P slots. The optimal value
``V_k = 1/2 z*' P z* + q' z* + M`` is the expected cost J^_k of MODEL.md §3.

Every solve takes any leading batch axes (``x_aug`` (..., K, 6): scenarios, psi values, AGVs).
Backends are named as in qpsolvers. ``"compiled"`` (the default) solves the whole stack in one
compiled call (:mod:`lawn_env.qp`: per axis, move blocking eliminated, warm-started from each
problem's previous working set, kept as plain arrays so that copies and pickles continue bitwise),
exact to rounding. The references solve one problem at a time through Python: ``"daqp"`` and
``"osqp"`` keep one persistent, warm-started workspace per problem; ``"qpsolvers:<name>"`` calls
any other qpsolvers backend (stateless). A problem the backend cannot settle goes to a cold DAQP
solve, then a cold OSQP solve at high accuracy, then the always-feasible zero sequence; fallbacks
are counted in the returned :class:`MPCSolution` (``status``), never raised.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
import numpy.typing as npt

from .dynamics import ACCELERATION, PredictionModel, command_mask, planning_period
from .products import matmul
from .qp import AxisPencils

if TYPE_CHECKING:
    from .config import ScenarioConfig

__all__ = ["MPCSolution", "OutageAwareMPC", "SlotData", "Rows", "BACKENDS", "DEFAULT_BACKEND"]

#: The backend every caller uses unless told otherwise.
DEFAULT_BACKEND = "compiled"


def _qp_value(x: np.ndarray, p: np.ndarray, q: np.ndarray) -> float:
    """``x'Px / 2 + q'x``, the objective at a fallback's answer, in one fixed order (:mod:`lawn_env.products`)."""
    return float(0.5 * matmul(matmul(x, p), x) + matmul(q, x))


@dataclass(frozen=True)
class MPCSolution:
    """Solution of the control QPs at one slot (leading axes as the solve's: (..., K))."""

    increments: np.ndarray  # (..., K, N_p, 2) Delta-mu_k, m/s^2
    value: np.ndarray  # (..., K) V_k = optimal J^_k
    status: np.ndarray  # (..., K) 0 primary backend, 1 fallback (DAQP or OSQP), 2 fallback zero sequence
    iterations: np.ndarray  # (..., K) solver iterations of the accepted solve
    solve_time_s: float

    @property
    def num_fallbacks(self) -> int:
        return int(np.count_nonzero(self.status))


@dataclass(frozen=True)
class SlotData:
    """The psi-independent data of one slot's QPs (see :meth:`OutageAwareMPC.prepare`)."""

    residual: np.ndarray  # r = C x~ - chi_ref, (..., K, 6(N_p+1))
    linear: np.ndarray  # F' Q4 r, (..., K, 2 N_p)
    constant: np.ndarray  # M = r' Q4 r, (..., K)
    lower: np.ndarray  # (..., K, 4 N_p): increment bounds, then bounds on T z
    upper: np.ndarray
    phase: Any = 0  # slot phase (slot % control period): an int, or one per scenario (...,)

    @functools.cached_property
    def phase_flat(self) -> np.ndarray:
        """The slot phase of every problem, flattened over (..., K): int64."""
        return np.broadcast_to(np.asarray(self.phase, dtype=np.int64)[..., None], self.constant.shape).reshape(-1)


#: A reference backend's answer to one QP: (z or None when it failed, iterations, objective).
Solved = tuple[np.ndarray | None, int, float]


class _DaqpBackend:
    """One persistent ``daqp.Model`` per problem index (dual active set, exact, warm-started)."""

    name = "daqp"

    def __init__(self, constraint_matrix: np.ndarray):
        import daqp

        self._daqp = daqp
        self._a = np.array(constraint_matrix, dtype=float, order="C")  # DAQP wants a writable buffer
        self._models: dict[int, Any] = {}

    def solve(self, k: int, p: np.ndarray, q: np.ndarray, lower: np.ndarray, upper: np.ndarray,
              bounds_changed: bool = True) -> Solved:
        model = self._models.get(k)
        if model is None:
            model = self._daqp.Model()
            exitflag, _ = model.setup(p, q, self._a, upper, lower)
            if exitflag < 0:
                return None, 0, 0.0
            self._models[k] = model
        else:
            flag = model.update(H=p, f=q, bupper=upper, blower=lower) if bounds_changed else model.update(H=p, f=q)
            if flag < 0:
                self._models.pop(k, None)
                return None, 0, 0.0
        x, fval, exitflag, info = model.solve()
        if exitflag != 1:
            self._models.pop(k, None)  # start the next solve from a fresh workspace
            return None, info.get("iterations", 0), 0.0
        return x, info["iterations"], fval


class _OsqpBackend:
    """One persistent ``osqp.OSQP`` per problem index, warm-started, polished, tight tolerances."""

    name = "osqp"
    settings: ClassVar[dict[str, Any]] = {"eps_abs": 1e-10, "eps_rel": 1e-10, "polishing": True,
                                          "polish_refine_iter": 10, "max_iter": 50000, "verbose": False,
                                          "warm_starting": True}

    def __init__(self, constraint_matrix: np.ndarray):
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
        self._solvers: dict[int, Any] = {}

    def solve(self, k: int, p: np.ndarray, q: np.ndarray, lower: np.ndarray, upper: np.ndarray,
              bounds_changed: bool = True) -> Solved:
        solver = self._solvers.get(k)
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
            self._solvers.pop(k, None)
            return None, int(res.info.iter), 0.0
        x = np.asarray(res.x)
        return x, int(res.info.iter), _qp_value(x, p, q)


class _QpsolversBackend:
    """Any qpsolvers backend by name, stateless."""

    def __init__(self, solver: str, constraint_matrix: np.ndarray):
        import qpsolvers

        if solver not in qpsolvers.available_solvers:
            raise ValueError(
                f"backend 'qpsolvers:{solver}': solver not installed; "
                f"available: {', '.join(qpsolvers.available_solvers)}"
            )
        self._qpsolvers = qpsolvers
        self._solver = solver
        self.name = f"qpsolvers:{solver}"
        self._g = np.vstack([constraint_matrix, -constraint_matrix])
        self._n = constraint_matrix.shape[1]

    def solve(self, k: int, p: np.ndarray, q: np.ndarray, lower: np.ndarray, upper: np.ndarray,
              bounds_changed: bool = True) -> Solved:
        n = self._n
        h = np.concatenate([upper[n:], -lower[n:]])
        x = self._qpsolvers.solve_qp(p, q, G=self._g, h=h, lb=lower[:n], ub=upper[:n], solver=self._solver)
        if x is None or not np.all(np.isfinite(x)):
            return None, 0, 0.0
        x = np.asarray(x)
        return x, 0, _qp_value(x, p, q)


class _CompiledBackend:
    """The whole stack in one compiled call (:class:`lawn_env.qp.AxisPencils`), warm-started from
    each problem's previous working set. The working sets are plain int8 arrays, one per shape of
    the calls' stacks and caller's key (a planner's psi table and its single evaluations, the RL
    interface's stakes at psi = 1 and its anchor keep theirs apart), so a copy or a pickle of the
    MPC continues bitwise like the original."""

    name = "compiled"

    def __init__(self, pencils: AxisPencils):
        self.pencils = pencils
        self.working_sets: dict[tuple[Any, ...], np.ndarray] = {}  # (stack shape, key) -> (M, 2, 2 N_p) int8

    def forget(self, rows: np.ndarray, lead: int) -> None:
        """Drop the warm starts of the scenarios ``rows`` of the stacks whose first axis has ``lead``
        entries."""
        for (shape, _), sets in self.working_sets.items():
            if shape and shape[0] == lead:
                sets.reshape(shape + sets.shape[1:])[rows] = 0

    def solve_all(self, key: tuple[Any, ...], s: np.ndarray, q: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                  phase: np.ndarray, start: tuple[Any, ...] | None = None, rows: Rows | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Solve the stack from the working sets kept under ``key`` (or copied from ``start``'s):
        (z, objective, iterations, settled) per problem. With ``rows`` the stack is those scenarios of a
        batch (:class:`Rows`), each from its own working sets, kept per scenario of the batch."""
        if rows is not None:
            return self._solve_rows(key, s, q, lower, upper, phase, rows)
        source = self.working_sets.get(start) if start is not None else None
        if source is not None:
            self.working_sets[key] = source.copy()
        sets = self.working_sets.get(key)
        if sets is None:
            sets = self.working_sets[key] = np.zeros((s.shape[0], 2, 2 * self.pencils.horizon), dtype=np.int8)
        if not (lower.flags.c_contiguous and upper.flags.c_contiguous):
            lower, upper = _writable(lower), _writable(upper)
        return self.pencils.solve(s, q, lower, upper, phase, sets)

    def _solve_rows(self, key: tuple[Any, ...], s: np.ndarray, q: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                    phase: np.ndarray, rows: Rows) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`solve_all` of the scenarios ``rows.index`` of a batch of ``rows.batch``: their working sets
        gathered from the batch's (kept under the batch's stack shape, so :meth:`forget` reaches them),
        solved, and put back. A scenario's sets change only when it is solved: it continues as when it
        is planned alone."""
        count = rows.index.size
        per = s.shape[0] // count  # the problems of one scenario (its AGVs)
        full = ((rows.batch, per), ("rows", key[1]))
        sets = self.working_sets.get(full)
        if sets is None:
            sets = self.working_sets[full] = np.zeros((rows.batch * per, 2, 2 * self.pencils.horizon), dtype=np.int8)
        by_row = sets.reshape(rows.batch, per, *sets.shape[1:])
        mine = np.ascontiguousarray(by_row[rows.index]).reshape(count * per, *sets.shape[1:])
        if not (lower.flags.c_contiguous and upper.flags.c_contiguous):
            lower, upper = _writable(lower), _writable(upper)
        solved = self.pencils.solve(s, q, lower, upper, phase, mine)
        by_row[rows.index] = mine.reshape(count, per, *sets.shape[1:])
        return solved


@dataclass(frozen=True)
class Rows:
    """Which scenarios of a batch a solve's stack holds: their indices ``index`` (a leading axis of the
    stack, in order) among ``batch`` scenarios that keep their own warm starts (a batched planner's)."""

    index: np.ndarray
    batch: int


#: The named backends.
BACKENDS = ("compiled", "daqp", "osqp")
#: A backend that solves one QP at a time through Python (the references of the compiled one).
ReferenceBackend = _DaqpBackend | _OsqpBackend | _QpsolversBackend


def _reference_backend(name: str, constraint_matrix: np.ndarray) -> ReferenceBackend:
    if name == "daqp":
        return _DaqpBackend(constraint_matrix)
    if name == "osqp":
        return _OsqpBackend(constraint_matrix)
    if name.startswith("qpsolvers:"):
        return _QpsolversBackend(name.split(":", 1)[1], constraint_matrix)
    raise ValueError(f"unknown QP backend {name!r}; valid: {', '.join(BACKENDS)}, or 'qpsolvers:<solver name>'")


class OutageAwareMPC:
    """The control QPs (P3) of K AGVs, over any leading batch axes.

    ``solve(x_aug, chi_ref, psi)`` returns the optimal increment sequences. Build with
    :meth:`from_config`. The same object serves the Comm environments, the RL interface's anchors
    and the experts.
    """

    def __init__(self, model: PredictionModel, num_agvs: int, accel_max: float, accel_increment_max: float,
                 backend: str = DEFAULT_BACKEND, control_period: int = 1, pencils: AxisPencils | None = None):
        if int(control_period) < 1:
            raise ValueError(f"control_period={control_period!r}: must be an integer >= 1")
        self.model = model
        # the compiled backend's pencils when the caller keeps them (a model not rebuilt from its key:
        # lawn_env.tail's); else the shared ones of the model's key
        self._given_pencils = pencils
        self.control_period = int(control_period)
        self.num_agvs = int(num_agvs)
        self.accel_max = float(accel_max)
        self.accel_increment_max = float(accel_increment_max)
        n = model.num_inputs
        self._n = n
        self._constraint = model.increment_sum
        self._q5_2 = 2.0 * np.asarray(model.q5)
        self._ftq4f_2 = 2.0 * np.asarray(model.ftq4f)
        masks = [command_mask(phase, model.horizon, self.control_period) for phase in range(self.control_period)]
        self.backend_name = backend
        self.backend = self._make_backend(backend)
        # increment bounds per slot phase: zero where move blocking holds the acceleration
        self._box_upper = np.stack([np.repeat(np.where(mask, self.accel_increment_max, 0.0), 2) for mask in masks])
        # the reference backends' last bounds (their workspaces keep them)
        self._last_bounds: tuple[np.ndarray, np.ndarray] | None = None

    def _make_backend(self, name: str) -> ReferenceBackend | _CompiledBackend:
        if name == "compiled":
            given = self._given_pencils
            return _CompiledBackend(given if given is not None else _pencils(self.model.key, self.control_period))
        return _reference_backend(name, self._constraint)

    def hessian(self, s: float) -> np.ndarray:
        """P = 2 G = 2 (psi^2 F'Q4F + Q5) of one AGV's QP at ``s`` = psi^2 (2 N_p x 2 N_p), for the
        reference backends, which take the full matrix."""
        return s * self._ftq4f_2 + self._q5_2

    def __getstate__(self) -> dict[str, Any]:
        """Copies and pickles carry the problem and the compiled backend's working sets (plain
        arrays: the copy continues bitwise); the reference backends' workspaces (C objects) are
        not carried, so such a copy starts its next solve cold."""
        state = self.__dict__.copy()
        if self.backend_name != "compiled":
            state["backend"] = None
        state["_last_bounds"] = None
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        if self.backend is None:
            self.backend = self._make_backend(self.backend_name)

    @classmethod
    def from_config(cls, config: ScenarioConfig, backend: str = DEFAULT_BACKEND,
                    terminal_success: float = 1.0, lag: bool = False) -> OutageAwareMPC:
        """The MPC of ``config`` (``terminal_success``, ``lag``: :meth:`PredictionModel.from_config`;
        with ``lag`` and an actuator lag in the config, its states have 8 entries)."""
        ctl = config.control
        return cls(PredictionModel.from_config(config, terminal_success, lag), config.num_agvs, ctl.accel_max_mps2,
                   ctl.accel_increment_max_mps2, backend=backend, control_period=planning_period(config))

    def reset(self, which: np.ndarray | None = None) -> None:
        """Drop the warm starts: the next solve starts cold, so an episode's solutions do not depend
        on the episodes before it. ``which`` (a boolean mask over the leading batch axis of the
        solves) drops only those scenarios' warm starts."""
        if which is not None:
            which = np.asarray(which, dtype=bool)
            rows = np.flatnonzero(which)
            if isinstance(self.backend, _CompiledBackend):
                self.backend.forget(rows, which.shape[0])
                return
        self.backend = self._make_backend(self.backend_name)
        self._last_bounds = None

    # ------------------------------------------------------------------ problem data
    def prepare(self, x_aug: np.ndarray, chi_ref: np.ndarray, slot: npt.ArrayLike | None = None) -> SlotData:
        """The parts of the QPs that do not depend on psi (one slot's state and reference; any
        leading batch axes ``x_aug`` (..., K, 6), ``chi_ref`` (..., K, N_p+1, 6)).

        ``slot`` (the current slot n) is required when the MPC plans with a control period > 1:
        increments are then allowed only at the slots n + i where a command goes out
        (:func:`lawn_env.dynamics.command_mask`); a batch takes one slot per scenario (...,)."""
        k, nx = self.num_agvs, self.model.state_dim
        window = self.model.horizon + 1
        lead = x_aug.shape[:-2]
        if x_aug.shape[-2:] != (k, nx) or chi_ref.shape != (*lead, k, window, 6):
            raise ValueError(f"x_aug has shape {x_aug.shape} and chi_ref {chi_ref.shape}; this MPC (num_agvs={k}, "
                             f"horizon={self.model.horizon}) needs ({k}, {nx}) and ({k}, {window}, 6), with any "
                             f"leading batch axes (..., K, {nx}) and (..., K, N_p+1, 6)")
        phase = self._phase(slot, lead)
        n = self._n
        flat_x = np.reshape(x_aug, (-1, nx))
        r = self.model.residual(flat_x, chi_ref.reshape(-1, window, 6))  # 2-D products over every problem
        lower, upper = self._bounds(flat_x, phase)
        shape = (*lead, k)
        return SlotData(
            residual=r.reshape((*shape, -1)),
            linear=matmul(r, self.model.ftq4.T).reshape((*shape, n)),  # F' Q4 r, so H = 2 psi (F' Q4 r)'
            constant=self.model.cost_to_go(r).reshape(shape),
            lower=lower.reshape((*shape, 2 * n)),
            upper=upper.reshape((*shape, 2 * n)),
            phase=phase,
        )

    def _phase(self, slot: npt.ArrayLike | None, lead: tuple[int, ...]) -> Any:
        """The slot phase (slot % control period) of each scenario: an int, or one per scenario ``lead``."""
        if self.control_period == 1:
            return 0
        if slot is None:
            raise ValueError(f"this MPC plans with control_period={self.control_period}: pass slot= (the current slot)")
        phase = np.asarray(slot, dtype=np.int64) % self.control_period
        if phase.shape not in ((), lead):
            raise ValueError(f"slot has shape {phase.shape}; expected a scalar or one per scenario {lead}")
        return int(phase) if phase.ndim == 0 else phase

    def _bounds(self, flat_x: np.ndarray, phase: Any) -> tuple[np.ndarray, np.ndarray]:
        """The QPs' lower and upper bounds (M, 4 N_p) of states ``flat_x`` (M, nx): the increment bounds
        (zero where move blocking holds the acceleration), then |u[n-1] + running sum| <= a_max."""
        n, k = self._n, self.num_agvs
        lower = np.empty((flat_x.shape[0], 2 * n))
        upper = np.empty((flat_x.shape[0], 2 * n))
        pos = self._box_upper[phase]  # (2 N_p,) or (..., 2 N_p), one row per scenario
        if np.ndim(phase):
            pos = np.repeat(pos.reshape(-1, n), k, axis=0)
        upper[:, :n] = pos
        np.negative(upper[:, :n], out=lower[:, :n])
        u_prev = np.tile(flat_x[:, ACCELERATION], self.model.horizon)  # u[n-1] repeated over the horizon
        np.subtract(self.accel_max, u_prev, out=upper[:, n:])
        np.subtract(-self.accel_max, u_prev, out=lower[:, n:])
        return lower, upper

    def objective_data(self, state: np.ndarray, linear: np.ndarray, constant: np.ndarray,
                       slot: npt.ArrayLike | None = None) -> SlotData:
        """The slot's QPs with a linear term ``linear`` (..., K, 2 N_p) and constant (..., K) of the
        caller's (the objective ``z' G z + 2 linear' z + constant``; G the model's), the bounds of
        ``state`` (..., K, nx) as :meth:`prepare`'s: for an objective that is not the tracking error's
        (:class:`lawn_env.tail.LossAwareTail`'s). The data carries no residual."""
        lead = state.shape[:-2]
        phase = self._phase(slot, lead)
        lower, upper = self._bounds(np.reshape(state, (-1, state.shape[-1])), phase)
        shape = (*lead, self.num_agvs)
        return SlotData(residual=np.empty((*shape, 0)), linear=linear, constant=constant,
                        lower=lower.reshape((*shape, 2 * self._n)), upper=upper.reshape((*shape, 2 * self._n)),
                        phase=phase)

    # ------------------------------------------------------------------ solve
    def solve(self, x_aug: np.ndarray, chi_ref: np.ndarray, psi: npt.ArrayLike,
              slot: npt.ArrayLike | None = None) -> MPCSolution:
        """Solve the QPs at success probabilities ``psi`` (..., K) (``slot`` as for :meth:`prepare`)."""
        return self.solve_prepared(self.prepare(x_aug, chi_ref, slot), psi)

    def solve_prepared(self, data: SlotData, psi: npt.ArrayLike, warm_key: str = "",
                       start_from: str | None = None, rows: Rows | None = None) -> MPCSolution:
        """Solve the QPs of a prepared slot at success probabilities ``psi`` (broadcast to the
        data's (..., K)): the planners call this many times with the same ``data``. ``data`` may
        also be evaluated at a stack of psi values with leading axes of their own, e.g. ``psi``
        (L, K) on data (K,): one call for a planner's psi table. Calls with another ``warm_key``
        keep warm starts of their own (a caller that alternates two kinds of solves of one shape);
        ``start_from`` names another key whose working sets (of the same shape) this solve starts
        from instead, when they exist (the compiled backend; the others ignore both). ``rows``: the data's
        leading axis is those scenarios of a batch, each warm-started from its own last solve (:class:`Rows`;
        the compiled backend)."""
        start = time.perf_counter()
        psi = np.asarray(psi, dtype=float)
        if not ((psi >= 0.0) & (psi <= 1.0)).all():  # NaN fails both
            bad = psi[~((psi >= 0.0) & (psi <= 1.0))].ravel()[0]
            raise ValueError(f"psi={bad!r}: success probabilities must lie in [0, 1]")
        n = self._n
        lead = data.constant.shape
        if psi.shape == lead:  # the common case: no broadcasting, the prepared arrays as they are
            count = data.constant.size
            lower, upper = data.lower.reshape(count, 2 * n), data.upper.reshape(count, 2 * n)
            phase = data.phase_flat
        else:
            try:
                lead = np.broadcast_shapes(psi.shape, lead)
            except ValueError:
                lead = ()
            if lead[-len(data.constant.shape):] != data.constant.shape:
                raise ValueError(f"psi has shape {psi.shape}; expected one per problem of the prepared data "
                                 f"{data.constant.shape}, with any leading axes of its own") from None
            psi = np.broadcast_to(psi, lead)
            count = int(np.prod(lead))
            lower = _writable(np.broadcast_to(data.lower, (*lead, 2 * n)).reshape(count, 2 * n))
            upper = _writable(np.broadcast_to(data.upper, (*lead, 2 * n)).reshape(count, 2 * n))
            phase = np.broadcast_to(np.asarray(data.phase, dtype=np.int64)[..., None], lead).reshape(count)
        q = ((2.0 * psi)[..., None] * data.linear).reshape(count, n)  # H' = 2 psi F'Q4 r
        s = (psi * psi).reshape(count)
        if isinstance(self.backend, _CompiledBackend):  # blocked increments come back exactly zero
            z, fval, iterations, settled = self.backend.solve_all((lead, warm_key), s, q, lower, upper, phase,
                                                                  None if start_from is None else (lead, start_from),
                                                                  rows)
            status = np.zeros(count, dtype=np.int8)
            if not settled.all():
                for i in np.flatnonzero(~settled).tolist():
                    z[i], fval[i], iterations[i], status[i] = self._fallback_solve(i, s[i], q[i], lower[i], upper[i])
        else:
            z, fval, iterations, status = self._solve_each(s, q, lower, upper)
        if self.control_period > 1:  # the blocked increments exactly zero (reference solvers return ~1e-14)
            z = np.clip(z, lower[:, :n], upper[:, :n])
        return MPCSolution(
            increments=z.reshape((*lead, self.model.horizon, 2)),
            value=fval.reshape(lead) + data.constant,
            status=status.reshape(lead),
            iterations=iterations.reshape(lead),
            solve_time_s=time.perf_counter() - start,
        )

    def _solve_each(self, s: np.ndarray, q: np.ndarray, lower: np.ndarray, upper: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The reference backends: one problem at a time, each with its own warm workspace."""
        count, n = q.shape
        last = self._last_bounds
        bounds_changed = last is None or not (np.array_equal(last[0], lower) and np.array_equal(last[1], upper))
        self._last_bounds = (lower.copy(), upper.copy())
        z = np.empty((count, n))
        fval = np.empty(count)
        status = np.zeros(count, dtype=np.int8)
        iterations = np.zeros(count, dtype=np.int64)
        backend = self.backend
        assert not isinstance(backend, _CompiledBackend)  # the reference backends solve one at a time
        for i in range(count):
            p = self.hessian(s[i])
            x, its, f = backend.solve(i, p, q[i], lower[i], upper[i], bounds_changed)
            if x is None:
                x, f, its, status[i] = self._fallback_solve(i, s[i], q[i], lower[i], upper[i])
            z[i], fval[i], iterations[i] = x, f, its
        return z, fval, iterations, status

    def _fallback_solve(self, i: int, s: float, q: np.ndarray, lower: np.ndarray, upper: np.ndarray
                        ) -> tuple[np.ndarray, float, int, int]:
        """A problem the backend did not settle: a cold DAQP solve, then a cold OSQP solve, then the
        zero sequence (feasible whenever ``|u[n-1]| <= a_max``, which the simulator keeps). Returns
        (z, objective, iterations, status 1 or 2)."""
        p = self.hessian(s)
        for name in ("daqp", "osqp"):
            if name == self.backend_name:
                continue
            x, its, _ = _reference_backend(name, self._constraint).solve(0, p, q, lower, upper)
            if x is not None:
                return x, _qp_value(x, p, q), its, 1
        return np.zeros(self._n), 0.0, 0, 2

    def command_stakes(self, data: SlotData) -> np.ndarray:
        """What delivering each AGV's command is worth this slot: ``V_k(0) - V_k(1)`` >= 0, the QP's
        optimal value when the command is sure to be lost minus when it is sure to arrive (any
        leading batch axes, (..., K)). At psi = 0 the increments never act, so zero is optimal
        (feasible, since the simulator keeps ``|u[n-1]| <= a_max``) and ``V_k(0) = r' Q4 r`` is the
        prepared constant; ``V_k(1)`` is one solve."""
        delivered = self.solve_prepared(data, np.ones(data.constant.shape), warm_key="stakes").value
        stakes: np.ndarray = np.maximum(data.constant - delivered, 0.0)
        return stakes


    def lost_command(self, data: SlotData, queue: np.ndarray | None = None) -> SlotData:
        """The slot's QPs with the next command lost: its increment held at zero, the AGV keeping
        u[n-1] until the command after it (MODEL.md §4, "Planning under delivery"); or, with ``queue``
        (..., K, L, 2), the increments a buffered actuator plays on the next slots without a packet
        (:func:`lawn_env.state.buffer_queue`; MODEL.md §3), pinned to the one it plays then
        (:meth:`_played`). The next command is the horizon's first increment that may be non-zero
        (:func:`command_mask`; the first with commands every slot; none when the period outlasts the
        horizon, and then nothing is held). Its phases are ``P .. 2P-1`` of the compiled pencils."""
        n, p, horizon = self._n, self.control_period, self.model.horizon
        phase = np.asarray(data.phase, dtype=np.int64)
        first = (p - phase) % p  # the horizon index of the next command: 0 on a command slot
        lower, upper = data.lower.copy(), data.upper.copy()
        held = np.zeros((*data.lower.shape[:-1], 2 * n), dtype=bool)
        first = np.broadcast_to(first[..., None], data.constant.shape)
        axes = 2 * np.minimum(first, horizon - 1)[..., None] + np.arange(2)
        np.put_along_axis(held, axes, True, axis=-1)
        held &= (first < horizon)[..., None]  # a period longer than the horizon: no command in it to hold
        lower[held], upper[held] = 0.0, 0.0
        lost_phase = int(phase) + p if phase.ndim == 0 else phase + p
        lost = SlotData(data.residual, data.linear, data.constant, lower, upper, lost_phase)
        return lost if queue is None else self._played(lost, first, queue)

    def _played(self, lost: SlotData, first: np.ndarray, queue: np.ndarray) -> SlotData:
        """:meth:`lost_command`'s QPs with the held increment (horizon index ``first``) at the buffered
        actuator's ``c`` instead of zero: the queue's element ``first`` (zero past its end: a spent
        buffer holds), clipped to the increment bound and saturated into the control set as the
        simulator does. The increments before ``first`` (slots without a command) stay zero, as a
        period-aware planner's plans have them (other increments there the simulator plays but this
        does not price). With z = c + w and
        w's held entries zero, ``z'Gz + 2 l'z + M`` (G = F'Q4F + Q5, psi = 1) is
        ``w'Gw + 2 (l + G c)'w + c'Gc + 2 l'c + M``, and the running-sum bounds from ``first`` on move by c."""
        n, horizon = self._n, self._n // 2
        queue = np.asarray(queue, dtype=float)
        length = queue.shape[-2]
        if queue.shape[:-2] != first.shape or queue.shape[-1] != 2:
            raise ValueError(f"queue has shape {queue.shape}; expected {(*first.shape, 'L', 2)}: the buffer's "
                             "increments of each AGV in the order it plays them")
        cols = 2 * np.minimum(first, horizon - 1)[..., None] + np.arange(2)  # the held increment's columns
        played = np.zeros((*first.shape, 2))
        if length:
            at = np.minimum(first, length - 1)[..., None, None].repeat(2, -1)
            played = np.where((first < length)[..., None], np.take_along_axis(queue, at, axis=-2)[..., 0, :], 0.0)
        played = np.clip(played, -self.accel_increment_max, self.accel_increment_max)
        sums = n + cols  # the running sums' bounds there: -a_max - u and a_max - u
        step = np.clip(played, np.take_along_axis(lost.lower, sums, -1), np.take_along_axis(lost.upper, sums, -1))
        flat = np.zeros((*first.shape, n))  # c
        np.put_along_axis(flat, cols, np.where((first < horizon)[..., None], step, 0.0), axis=-1)
        shift = matmul(flat, 0.5 * self.hessian(1.0))  # G c, G of psi = 1
        constant = lost.constant + np.einsum("...b,...b->...", shift + 2.0 * lost.linear, flat)
        offset = np.cumsum(flat.reshape((*first.shape, horizon, 2)), axis=-2).reshape(flat.shape)  # c's running sums
        lower, upper = lost.lower.copy(), lost.upper.copy()
        lower[..., n:] -= offset
        upper[..., n:] -= offset
        return SlotData(lost.residual, lost.linear + shift, constant, lower, upper, lost.phase)

    def delivery_values(self, data: SlotData, queue: np.ndarray | None = None,
                        rows: Rows | None = None) -> tuple[MPCSolution, np.ndarray]:
        """The two MPC values of each AGV's next command (any leading batch axes, (..., K)): the
        solution at psi = 1 (every planned increment delivered: its increments and ``value`` V^del)
        and V^lost, the same problem's optimum with the next command lost (:meth:`lost_command`: held
        at zero, or with a buffered actuator's ``queue`` the buffer's increment played).
        The expected cost of a command sent with success probability psi is
        ``psi V^del + (1 - psi) V^lost`` (MODEL.md §4, "Planning under delivery"); ``V^lost - V^del``
        >= 0 is what its delivery is worth. ``rows``: :meth:`solve_prepared`'s."""
        ones = np.ones(data.constant.shape)
        delivered = self.solve_prepared(data, ones, warm_key="delivered", rows=rows)
        lost = self.solve_prepared(self.lost_command(data, queue), ones, warm_key="lost", rows=rows)
        return delivered, np.maximum(lost.value, delivered.value)


def _writable(arr: np.ndarray) -> np.ndarray:
    """C-contiguous and writable (the compiled kernel and DAQP take such buffers; no copy when it is)."""
    return np.require(arr, dtype=float, requirements=("C", "W"))


@functools.lru_cache(maxsize=32)
def _pencils(model_key: tuple[Any, ...], period: int) -> AxisPencils:
    """The per-axis pencils of the prediction model built from ``model_key``
    (:attr:`~lawn_env.dynamics.PredictionModel.key`) and a control period, built once per pair of
    values and shared."""
    model = PredictionModel.from_key(model_key)
    masks = [command_mask(phase, model.horizon, period) for phase in range(period)]
    lost = [mask.copy() for mask in masks]  # phases P .. 2P-1: the next command held (lost_command)
    for phase, mask in enumerate(lost):
        if (period - phase) % period < model.horizon:  # a period longer than the horizon: maybe none in it
            mask[(period - phase) % period] = False
    return AxisPencils.build(2.0 * model.q5, 2.0 * model.ftq4f, model.horizon, masks + lost)
