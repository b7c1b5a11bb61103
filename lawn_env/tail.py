"""Planning under loss: each AGV's next command with the future priced under loss (MODEL.md §4,
"Planning under loss").

In the augmented state z = x~ a lost command is a zero increment (the AGV holds u[n-1]), so every AGV
is a linear system with Bernoulli actuation loss and acknowledgements (the drone sees at the next slot
whether a command arrived and replans). With every later command delivered with probability psi-bar
and replanned from the state it leads to, the expected cost-to-go of stage i is quadratic,

    V_i(z) = z' P_i z - 2 g_i' z + c_i,

with, on a stage where a command goes out (the effort of a delivered increment charged, as the
simulator charges it),

    V_i(z) = e_i' Q e_i + psi-bar min_d [d' R d + V_{i+1}(A z + B d)] + (1 - psi-bar) V_{i+1}(A z),

and on a stage without one (a control period P > 1: the AGV holds) ``e_i' Q e_i + V_{i+1}(A z)``;
e_i = z - ref_i, Q = Q1 and R = Q2 the MPC's weights. Unconstrained, the recursion is closed:

    M_i = R + B'P_{i+1}B,   L_i = M_i^-1 B'P_{i+1}A,   X_i = A'P_{i+1}B M_i^-1 B'P_{i+1}A,
    P_i = Q + A'P_{i+1}A - psi-bar X_i,       g_i = Q ref_i + (A - psi-bar B L_i)' g_{i+1},

the modified Riccati recursion of Schenato, Sinopoli, Franceschetti, Poolla and Sastry (Proc. IEEE
2007) on the augmented system, with the reference's affine terms. Its stationary solution
(:func:`lawn_env.dynamics.modified_riccati`; with a period, the periodic one) is the terminal weight
P_N, so every stage after the command is priced under loss. The certainty-equivalent MPC (every later
command delivered, the loss-free DARE behind it) implies a gain that loses mean-square stability below
a critical psi; the loss-aware gain L(psi) is stable for every psi > 0.

**The bounds.** The recursion knows no bounds on the later commands, and where they bind (an AGV that
must brake at a_max) a plan that counts on unbounded later corrections runs away. So the command
comes from a QP over the horizon that has the recursion's value and the MPC's bounds: the
deterministic problem with stage weights ``Q~_i = Q + (1 - psi-bar) X_i`` on the later command stages,
``Q`` elsewhere, terminal weight P_N and the linear terms ``h_i = Q ref_i + (1 - psi-bar) L_i' B' g_{i+1}``
(``h_N = P_N ref_N``) has, unconstrained, the same P_i and g_i after the command (its Riccati
recursion with Q~ is the loss-aware one, its gain L_i the loss-aware gain), so its first command and
the difference V^lost - V^del are the loss-aware ones; constrained, its plan keeps the bounds. The
bounds of a later command hold where the plan's delivered path is likely, while ``psi-bar^j >=
bounds_probability`` for the j-th command after this one (at low psi-bar the all-delivered path is
not the future: its bounds would bind where no AGV will be); the first command's always hold.

    V^del = the QP's optimum,    V^lost = the same with the next command held at zero,

the two values of :meth:`lawn_env.mpc.OutageAwareMPC.delivery_values`, here under loss (up to a term
that does not depend on the command). At psi-bar = 1 with every bound kept the QP is the
certainty-equivalent MPC's.

psi-bar is the expected delivery of the commands that matter, :func:`expected_delivery`: a running
average of ``sum_k psi_k w_k / sum_k w_k`` with w_k = V_k^lost - V_k^del (one value for the fleet: a
value per AGV starves AGVs, since a low psi-bar lowers the worth of delivering that AGV's command,
and with it its power and its psi). The tail is tabulated on :data:`PSI_GRID` (psi-bar rounded to it).
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import numpy.typing as npt
from scipy import linalg

from .dynamics import (
    ACCELERATION,
    PlanningSystem,
    PredictionModel,
    command_mask,
    increment_sum_matrix,
    loss_aware_gain,
    modified_riccati,
    planning_system,
)
from .mpc import DEFAULT_BACKEND, MPCSolution, OutageAwareMPC, Rows
from .products import matmul
from .qp import AxisPencils

if TYPE_CHECKING:
    from .config import ScenarioConfig

__all__ = ["LossAwareTail", "DeliveryLaw", "TailModel", "tail_model", "shared_tail", "expected_delivery",
           "first_delivery", "PSI_GRID", "PSI_FLOOR", "TAILS", "BOUNDS_PROBABILITY", "DELIVERY_MEMORY",
           "DELIVERY_START_ITERATIONS"]

#: The tails a delivery-value planner can price the future with: ``"loss-aware"`` (this module) and
#: ``"certainty-equivalent"`` (every later command delivered: the psi = 1 MPC and its DARE).
TAILS = ("loss-aware", "certainty-equivalent")

#: The loss-aware tail's defaults, shared by ``dv-mpc`` (:class:`agents.DeliverySettings`) and the AGVs'
#: ``control.law="delivery"`` (:class:`DeliveryLaw`): the later bounds' probability, psi-bar's memory and
#: the fixed-point steps of its first value.
BOUNDS_PROBABILITY = 0.3
DELIVERY_MEMORY = 0.5
DELIVERY_START_ITERATIONS = 3

#: The lowest psi-bar the tail plans for: below it the cost-to-go grows past 1e9 times the loss-free one.
PSI_FLOOR = 0.02
#: The values of psi-bar the tail is tabulated at: steps of 0.01 from :data:`PSI_FLOOR` to 1.
PSI_GRID = np.round(np.arange(round(PSI_FLOOR * 100), 101) / 100.0, 2)


def expected_delivery(previous: npt.ArrayLike, psi: np.ndarray, worth: np.ndarray, memory: float) -> np.ndarray:
    """The next psi-bar: ``memory * previous + (1 - memory) * sum_k psi_k w_k / sum_k w_k`` over the AGVs
    (the last axis of ``psi`` and ``worth``, any leading axes: one psi-bar per scenario); where no
    command is worth anything (sum w = 0) psi-bar stays."""
    previous = np.asarray(previous, dtype=float)
    total = worth.sum(axis=-1)
    weighted = np.divide((psi * worth).sum(axis=-1), total, out=np.array(previous, dtype=float, copy=True),
                         where=total > 0)
    result: np.ndarray = memory * previous + (1.0 - memory) * weighted
    return result


def first_delivery(worth_at: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], iterations: int,
                   shape: tuple[int, ...] = ()) -> np.ndarray:
    """psi-bar at an episode's first slot (one per scenario, ``shape``): ``iterations`` fixed-point steps
    from 1 of psi-bar -> the worth-weighted success ``sum_k psi_k w_k / sum_k w_k``, with
    ``worth_at(psi_bar)`` the slot's (psi_k, w_k) (..., K) at that psi-bar (a planner's search, or the
    drone's decided power and position)."""
    psi_bar = np.ones(shape)
    for _ in range(iterations):
        psi, worth = worth_at(psi_bar)
        psi_bar = expected_delivery(psi_bar, psi, worth, 0.0)
    return psi_bar


class _Stages(NamedTuple):
    """The recursion over the horizon for one psi-bar and slot phase: ``quad`` (N+1, n, n) the P_i (P_N
    the terminal weight), ``carry`` (N, n, n) (A - psi B L_i)' (A' on a hold stage), ``push`` (N, n, n)
    (1 - psi) L_i' B' (zero on a hold stage), ``weight`` (N, n, n) the stage weights Q~_i of the QP and
    ``command`` (N,) where a command goes out; ``first`` the next command's stage."""

    quad: np.ndarray
    carry: np.ndarray
    push: np.ndarray
    weight: np.ndarray
    command: np.ndarray
    first: int


class _Maps(NamedTuple):
    """The QP's objective as linear maps of the state z and the reference window (flattened):
    ``linear = z @ zf - ref @ rf``, ``constant = z'zz z - 2 z'zr ref + ref'rr ref``."""

    zf: np.ndarray
    rf: np.ndarray
    zz: np.ndarray
    zr: np.ndarray
    rr: np.ndarray


class TailModel:
    """The loss-aware tail of one system (:class:`lawn_env.dynamics.PlanningSystem`: the transition A, B
    of its n-state, the weights Q (n x n) and R (2 x 2), the horizon N, the control period P and the
    prediction matrices): per psi-bar on :data:`PSI_GRID` and slot phase, the recursion of the module
    docstring, its QP's prediction model and the QP's compiled pencils, built on first use and kept
    (read-only; shared by every tail of the system: :func:`shared_tail`)."""

    def __init__(self, system: PlanningSystem):
        self.system = system
        self.a, self.b, self.q, self.r = system.a, system.b, system.q, system.r
        self.horizon, self.period, self.slot_s, self.key = system.horizon, system.period, system.slot_s, system.key
        self.state_dim = system.state_dim
        self.c, self.f = system.c, system.f
        self._terminal: dict[int, np.ndarray] = {}
        self._stages: dict[tuple[int, int], _Stages] = {}
        self._models: dict[tuple[int, int], tuple[PredictionModel, AxisPencils]] = {}
        self._maps: dict[tuple[int, int], _Maps] = {}

    @staticmethod
    def grid_index(psi_bar: npt.ArrayLike) -> np.ndarray:
        """The index on :data:`PSI_GRID` of each psi-bar (rounded to the nearest point, clipped to it)."""
        psi = np.clip(np.asarray(psi_bar, dtype=float), PSI_FLOOR, 1.0)
        index: np.ndarray = np.rint((psi - PSI_FLOOR) * 100.0).astype(np.int64)
        return index

    def _step(self, p_next: np.ndarray, psi: float, command: bool
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One stage back from P_{i+1}: (P_i, carry_i, push_i, Q~_i)."""
        a, b, q = self.a, self.b, self.q
        n = self.state_dim
        if not command:
            return q + matmul(matmul(a.T, p_next), a), a.T, np.zeros((n, n)), q
        gain = loss_aware_gain(a, b, self.r, p_next)  # L_i
        at_p = matmul(a.T, p_next)
        x = matmul(matmul(at_p, b), gain)  # X_i
        p = q + matmul(at_p, a) - psi * x
        weight = q + (1.0 - psi) * x
        return (0.5 * (p + p.T), (a - psi * matmul(b, gain)).T, (1.0 - psi) * matmul(gain.T, b.T),
                0.5 * (weight + weight.T))

    def terminal(self, index: int) -> np.ndarray:
        """The stationary cost-to-go at psi-bar = PSI_GRID[index], per slot phase (P, n, n): the modified
        Riccati equation's solution, with a period the periodic one (commands at phase 0), by value
        iteration from the one above it on the grid (the solutions rise as psi-bar falls), from the DARE at
        psi-bar = 1 down: one chain, so a value never depends on which ones were asked for before."""
        for i in range(PSI_GRID.size - 1, index - 1, -1):
            if i not in self._terminal:
                self._terminal[i] = self._stationary(i)
        return self._terminal[index]

    def _stationary(self, index: int) -> np.ndarray:
        psi = float(PSI_GRID[index])
        above = self._terminal.get(index + 1)
        if self.period == 1:
            values = modified_riccati(self.a, self.b, self.q, self.r, psi, start=None if above is None else above[0])
            values = values[None]
        else:
            start = modified_riccati(self.a, self.b, self.q, self.r, psi) if above is None else above[0]
            values = self._periodic(psi, start)
        values.setflags(write=False)
        return values

    def _periodic(self, psi: float, start: np.ndarray) -> np.ndarray:
        """The periodic solution (phases 0..P-1, a command at phase 0) by value iteration over periods."""
        head = start
        for _ in range(1_000_000):
            values = [head]
            for phase in range(self.period - 1, -1, -1):
                values.append(self._step(values[-1], psi, phase == 0)[0])
            scale = float(np.abs(values[-1]).max())
            if not math.isfinite(scale):
                break
            if np.abs(values[-1] - head).max() <= 1e-12 * scale:
                return np.stack(values[::-1][: self.period])  # phases 0, 1, ..., P-1
            head = values[-1]
        raise ValueError(f"psi={psi!r}: the periodic modified Riccati equation does not converge")

    def stages(self, index: int, phase: int) -> _Stages:
        """The recursion over the horizon of a slot at ``phase`` (slot % P) at psi-bar = PSI_GRID[index]."""
        key = (index, phase)
        if key in self._stages:
            return self._stages[key]
        psi, n, dim = float(PSI_GRID[index]), self.horizon, self.state_dim
        quad = np.empty((n + 1, dim, dim))
        carry, push, weight = np.empty((n, dim, dim)), np.empty((n, dim, dim)), np.empty((n, dim, dim))
        command = command_mask(phase, n, self.period)
        first = int(np.argmax(command))
        quad[n] = self.terminal(index)[(phase + n) % self.period]
        for i in range(n - 1, -1, -1):
            later = bool(command[i]) and i > first  # this slot's command is planned as delivered
            quad[i], carry[i], push[i], weight[i] = self._step(quad[i + 1], psi, later)
        for arr in (quad, carry, push, weight, command):
            arr.setflags(write=False)
        stages = self._stages[key] = _Stages(quad, carry, push, weight, command, first)
        return stages

    def maps(self, index: int, phase: int) -> _Maps:
        """The QP objective's linear maps (:meth:`_objective_maps`) for a slot at ``phase`` at psi-bar =
        PSI_GRID[index]."""
        self.qp(index, phase)
        return self._maps[(index, phase)]

    def qp(self, index: int, phase: int) -> tuple[PredictionModel, AxisPencils]:
        """The QP's prediction model (stage weights Q~_i, terminal P_N over this system's prediction) and
        its compiled pencils, for a slot at ``phase`` at psi-bar = PSI_GRID[index]."""
        key = (index, phase)
        if key in self._models:
            return self._models[key]
        stages = self.stages(index, phase)
        q4 = linalg.block_diag(*stages.weight, stages.quad[-1])
        q5 = linalg.block_diag(*([self.r] * self.horizon))
        ftq4 = matmul(self.f.T, q4)
        arrays = {"a_aug": self.a, "b_aug": self.b, "q1": self.q, "q2": self.r, "q3": stages.quad[-1], "c": self.c,
                  "f": self.f, "q4": q4, "q5": q5, "ftq4f": matmul(ftq4, self.f), "ftq4": ftq4,
                  "increment_sum": increment_sum_matrix(self.horizon)}
        for arr in arrays.values():
            arr.setflags(write=False)
        model = PredictionModel(slot_s=self.slot_s, horizon=self.horizon, q1_tiled=None,
                                key=("loss-aware", *self.key, index, phase), **arrays)
        masks = [command_mask(ph, self.horizon, self.period) for ph in range(self.period)]
        lost = [mask.copy() for mask in masks]  # phases P .. 2P-1: the next command held (lost_command)
        for ph, mask in enumerate(lost):
            mask[(self.period - ph) % self.period] = False
        pencils = AxisPencils.build(2.0 * q5, 2.0 * model.ftq4f, self.horizon, masks + lost)
        self._models[key] = (model, pencils)
        self._maps[key] = self._objective_maps(stages, model)
        return model, pencils

    def _objective_maps(self, stages: _Stages, model: PredictionModel) -> _Maps:
        """The QP's objective as linear maps of the state z and the reference window ref (module
        docstring): the linear terms h = ref @ H (H from the recursion of h_i, applied to a basis), so
        ``linear = z @ (C'Q4F) - ref @ (H F)`` and ``constant = z'(C'Q4C)z - 2 z'(C'H')ref + ref'Q4 ref``."""
        n, horizon = self.state_dim, self.horizon
        size = n * (horizon + 1)
        basis = np.eye(size).reshape(size, horizon + 1, n)  # every reference window of one unit entry
        h = np.empty(basis.shape)
        g = matmul(basis[:, horizon], stages.quad[horizon])
        h[:, horizon] = g
        for i in range(horizon - 1, -1, -1):
            weighted = matmul(basis[:, i], self.q)
            h[:, i] = weighted + matmul(g, stages.push[i].T)
            g = weighted + matmul(g, stages.carry[i].T)
        hmat = h.reshape(size, size)
        c, f, q4 = model.c, model.f, model.q4
        ctq4 = matmul(c.T, q4)
        maps = _Maps(matmul(ctq4, f), matmul(hmat, f), matmul(ctq4, c), matmul(c.T, hmat.T), q4)
        for arr in maps:
            arr.setflags(write=False)
        return maps


@functools.lru_cache(maxsize=16)
def shared_tail(system: PlanningSystem) -> TailModel:
    """The :class:`TailModel` of ``system``, shared by every tail of it."""
    return TailModel(system)


def tail_model(slot_s: float, horizon: int, q1_diag: tuple[float, ...], q2_diag: tuple[float, ...], period: int,
               alpha: float = -1.0) -> TailModel:
    """The shared :class:`TailModel` of a system (:func:`lawn_env.dynamics.planning_system`): the augmented
    AGV (x~, 6 states) or, with an actuator lag (``alpha`` >= 0, :func:`lawn_env.dynamics.lag_alpha`), the
    lag's 8-state (x~ and the applied acceleration; Q1 weighs x~ alone)."""
    return shared_tail(planning_system(slot_s, horizon, q1_diag, q2_diag, period, alpha))


class LossAwareTail:
    """V^del, V^lost and the planned increments of K AGVs with the future priced under loss (module
    docstring), over any leading batch axes (one psi-bar and one slot per scenario). Each tail keeps its
    own QPs' warm starts (:meth:`reset` drops them), so an episode does not depend on the ones before.

    :meth:`delivery_values` takes the MPC's state (x~ (..., K, 6), or with ``lag`` the 8-state of
    :class:`agents.estimation.AGVTracker`) and the reference window (..., K, N_p+1, 6), and returns what
    :meth:`lawn_env.mpc.OutageAwareMPC.delivery_values` returns."""

    def __init__(self, model: TailModel, num_agvs: int, accel_max: float, accel_increment_max: float,
                 bounds_probability: float = BOUNDS_PROBABILITY, backend: str = DEFAULT_BACKEND, warm: bool = True):
        if not 0.0 < bounds_probability <= 1.0:
            raise ValueError(f"bounds_probability={bounds_probability!r}: must lie in (0, 1]")
        self.model = model
        self.num_agvs = int(num_agvs)
        self.accel_max, self.accel_increment_max = float(accel_max), float(accel_increment_max)
        self.bounds_probability = float(bounds_probability)
        self.backend = backend
        self.warm = warm  # False: every solve starts cold (its result a function of its problem alone)
        self._mpcs: dict[tuple[int, int], OutageAwareMPC] = {}
        self._released_cache: dict[tuple[int, int], np.ndarray | None] = {}

    @classmethod
    def from_config(cls, config: ScenarioConfig, lag: bool = False, bounds_probability: float = BOUNDS_PROBABILITY,
                    backend: str = DEFAULT_BACKEND, warm: bool = True) -> LossAwareTail:
        """The tail of ``config``'s AGVs (its horizon, weights, bounds and the control period the planners
        know); ``lag`` predicts with its actuator lag, where it has one."""
        ctl = config.control
        model = shared_tail(PlanningSystem.from_config(config, lag))
        return cls(model, config.num_agvs, ctl.accel_max_mps2, ctl.accel_increment_max_mps2, bounds_probability,
                   backend, warm)

    @property
    def state_dim(self) -> int:
        return int(self.model.state_dim)

    def reset(self, which: np.ndarray | None = None) -> None:
        """Drop every QP's warm starts (``which``: a mask over a batch's scenarios, only theirs)."""
        for mpc in self._mpcs.values():
            mpc.reset(which)

    def _mpc(self, index: int, phase: int) -> OutageAwareMPC:
        key = (index, phase)
        if key not in self._mpcs:
            model, pencils = self.model.qp(index, phase)
            self._mpcs[key] = OutageAwareMPC(model, self.num_agvs, self.accel_max, self.accel_increment_max,
                                             backend=self.backend, control_period=self.model.period,
                                             pencils=pencils)
        return self._mpcs[key]

    def references(self, chi_ref: np.ndarray) -> np.ndarray:
        """The reference of the model's state (..., N+1, n) from the window (..., N_p+1, 6): the lag's
        applied acceleration follows the reference acceleration; a window shorter than the tail's
        horizon is extended by its last entry."""
        horizon = self.model.horizon
        if chi_ref.shape[-2] < horizon + 1:
            pad = np.repeat(chi_ref[..., -1:, :], horizon + 1 - chi_ref.shape[-2], axis=-2)
            chi_ref = np.concatenate([chi_ref, pad], axis=-2)
        ref = chi_ref[..., : horizon + 1, :]
        if self.model.state_dim == 6:
            return ref
        return np.concatenate([ref, ref[..., ACCELERATION]], axis=-1)

    def delivery_values(self, state: np.ndarray, chi_ref: np.ndarray, psi_bar: npt.ArrayLike,
                        slot: npt.ArrayLike = 0, queue: np.ndarray | None = None,
                        rows: Rows | None = None) -> tuple[MPCSolution, np.ndarray]:
        """(the delivered solution: the planned increments (..., K, N, 2) and V^del (..., K); V^lost
        (..., K)) at psi-bar and slot (each one per scenario (...), or one for all). Under the buffered
        actuator ``queue`` (..., K, L, 2) is what each AGV plays without a packet
        (:func:`lawn_env.state.buffer_queue`), and V^lost plays it (:meth:`OutageAwareMPC.lost_command`).
        ``rows``: the leading axis is those scenarios of a batch, each continuing its own warm starts
        (:class:`lawn_env.mpc.Rows`; a batched planner's: its scenarios decide as each would alone)."""
        start = time.perf_counter()
        n, k = self.model.state_dim, self.num_agvs
        state = np.asarray(state, dtype=float)
        lead = state.shape[:-2]
        if state.shape[-2:] != (k, n) or chi_ref.shape[:-2] != (*lead, k) or chi_ref.shape[-1] != 6:
            raise ValueError(f"state has shape {state.shape} and chi_ref {chi_ref.shape}; this tail needs "
                             f"(..., {k}, {n}) and (..., {k}, N_p+1, 6)")
        scenarios = int(np.prod(lead))
        index = self.model.grid_index(psi_bar).reshape(-1)
        slots = np.asarray(slot, dtype=np.int64).reshape(-1)
        flat_z = state.reshape(scenarios, k, n)
        flat_ref = self.references(np.asarray(chi_ref, dtype=float)).reshape(scenarios, k, -1, n)
        flat_queue = None if queue is None else np.asarray(queue, dtype=float).reshape(scenarios, k, -1, 2)
        if rows is None and index.size == 1 and (
                slots.size == 1 or np.all(slots % self.model.period == slots[0] % self.model.period)):
            solution, lost = self._solve(int(index[0]), int(slots[0] % self.model.period), flat_z, flat_ref, slots,
                                         flat_queue)
        else:  # scenarios at other psi-bars or phases: one QP stack per group
            solution, lost = self._groups(np.broadcast_to(index, (scenarios,)), np.broadcast_to(slots, (scenarios,)),
                                          flat_z, flat_ref, flat_queue, rows)
        shape = (*lead, k)
        horizon = self.model.horizon
        return (MPCSolution(increments=solution.increments.reshape((*shape, horizon, 2)),
                            value=solution.value.reshape(shape), status=solution.status.reshape(shape),
                            iterations=solution.iterations.reshape(shape), solve_time_s=time.perf_counter() - start),
                lost.reshape(shape))

    def _groups(self, index: np.ndarray, slots: np.ndarray, z: np.ndarray, ref: np.ndarray,
                queue: np.ndarray | None, rows: Rows | None = None) -> tuple[MPCSolution, np.ndarray]:
        """:meth:`_solve` per group of scenarios sharing psi-bar and phase, reassembled (``rows``: the
        scenarios' places in their batch)."""
        scenarios, k = z.shape[:2]
        increments = np.zeros((scenarios, k, self.model.horizon, 2))
        delivered, lost = np.empty((scenarios, k)), np.empty((scenarios, k))
        status, iterations = np.zeros((scenarios, k), np.int8), np.zeros((scenarios, k), np.int64)
        groups = index * self.model.period + slots % self.model.period
        for group in np.unique(groups).tolist():
            mine = np.flatnonzero(groups == group)
            batch = None if rows is None else Rows(rows.index[mine], rows.batch)
            solution, lost[mine] = self._solve(*divmod(int(group), self.model.period), z[mine], ref[mine], slots[mine],
                                               None if queue is None else queue[mine], batch)
            increments[mine], delivered[mine] = solution.increments, solution.value
            status[mine], iterations[mine] = solution.status, solution.iterations
        return MPCSolution(increments, delivered, status, iterations, 0.0), lost

    def _solve(self, index: int, phase: int, z: np.ndarray, ref: np.ndarray, slots: np.ndarray,
               queue: np.ndarray | None = None, batch: Rows | None = None) -> tuple[MPCSolution, np.ndarray]:
        """One group of scenarios sharing psi-bar and phase: z (B, K, n), ref (B, K, N+1, n), the
        buffered actuator's queue (B, K, L, 2) or None; ``batch``: the scenarios' places in their batch."""
        stages = self.model.stages(index, phase)
        mpc = self._mpc(index, phase)
        maps = self.model.maps(index, phase)
        rows = z.shape[0] * z.shape[1]
        zr, rr = z.reshape(rows, -1), ref.reshape(rows, -1)
        linear = (matmul(zr, maps.zf) - matmul(rr, maps.rf)).reshape((*z.shape[:2], -1))
        constant = ((matmul(zr, maps.zz) * zr).sum(-1) - 2.0 * (matmul(zr, maps.zr) * rr).sum(-1)
                    + (matmul(rr, maps.rr) * rr).sum(-1))
        data = mpc.objective_data(z, linear, constant.reshape(z.shape[:2]), slots if slots.size > 1 else slots[0])
        if not self.warm:
            mpc.reset()
        released = self._released(index, phase, stages)
        if released is not None:
            data.lower[..., released] = -np.inf
            data.upper[..., released] = np.inf
        return mpc.delivery_values(data, queue, batch)

    def _released(self, index: int, phase: int, stages: _Stages) -> np.ndarray | None:
        """The bounds (columns of the QPs' (4 N,) bounds) of the later commands, and of the accelerations
        from them on, that the plan's delivered path reaches with probability below
        ``bounds_probability`` (module docstring); None when every bound holds."""
        key = (index, phase)
        if key in self._released_cache:
            return self._released_cache[key]
        psi = float(PSI_GRID[index])
        released = None
        if psi < 1.0:
            commands = np.cumsum(stages.command) - 1  # the j-th command after this one, at each stage
            kept = max(0, math.floor(math.log(self.bounds_probability) / math.log(psi) + 1e-9))
            free = (commands > kept) & (np.arange(stages.command.size) > stages.first)
            if free.any():  # increments and running sums, axes interleaved; held increments stay at zero
                released = np.concatenate([np.repeat(free & stages.command, 2), np.repeat(free, 2)])
        self._released_cache[key] = released
        return released


class DeliveryLaw:
    """The AGVs' law ``control.law="delivery"`` (the Comm envs' controller, the RL interface's MPC anchor):
    each AGV applies the loss-aware tail's command (:class:`LossAwareTail`, planned from the state the
    drone observes) at the fleet's psi-bar, which the drone sends with the commands. psi-bar follows the
    rule of ``dv-mpc`` (:func:`expected_delivery`, :data:`DELIVERY_MEMORY`) from the success
    probabilities the drone's decisions give; at an episode's first slot, the fixed point
    (:func:`first_delivery`, :data:`DELIVERY_START_ITERATIONS` steps) at that slot's decision. One psi-bar
    per scenario of a batch; every solve starts cold, so a scenario's commands do not depend on the
    others'."""

    def __init__(self, config: ScenarioConfig, backend: str = DEFAULT_BACKEND):
        self.tail = LossAwareTail.from_config(config, backend=backend, warm=False)
        self.psi_bar: np.ndarray | None = None  # per scenario; NaN: a new episode's first slot

    def reset(self, which: np.ndarray | None = None) -> None:
        """New episodes for the scenarios ``which`` (a mask over the batch; all when None)."""
        if self.psi_bar is None or which is None:
            self.psi_bar = None
        else:
            self.psi_bar[np.asarray(which, dtype=bool).reshape(self.psi_bar.shape)] = np.nan

    def solve(self, state: np.ndarray, chi_ref: np.ndarray, psi: np.ndarray, slot: npt.ArrayLike,
              queue: np.ndarray | None = None) -> MPCSolution:
        """The AGVs' planned increments (..., K, N, 2) at the success probabilities ``psi`` (..., K) of the
        drone's decisions; advances psi-bar by this slot (the commands' worth with the buffered
        actuator's ``queue`` (..., K, L, 2) played on a loss, where given)."""
        lead = state.shape[:-2]
        if self.psi_bar is None or self.psi_bar.shape != lead:
            self.psi_bar = np.full(lead, np.nan)
        unset = np.isnan(self.psi_bar)
        if unset.any():
            rows = np.flatnonzero(unset.reshape(-1))
            flat = self.psi_bar.reshape(-1)
            slots = np.broadcast_to(np.asarray(slot, dtype=np.int64), lead).reshape(-1)[rows]
            z = state.reshape(-1, *state.shape[-2:])[rows]
            ref = chi_ref.reshape(-1, *chi_ref.shape[-3:])[rows]
            decided = psi.reshape(-1, psi.shape[-1])[rows]
            played = None if queue is None else queue.reshape(-1, *queue.shape[-3:])[rows]

            def worth_at(psi_bar: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
                solution, lost = self.tail.delivery_values(z, ref, psi_bar, slots, played)
                return decided, lost - solution.value

            flat[rows] = first_delivery(worth_at, DELIVERY_START_ITERATIONS, (rows.size,))
        solution, lost = self.tail.delivery_values(state, chi_ref, self.psi_bar, slot, queue)
        self.psi_bar = expected_delivery(self.psi_bar, psi, lost - solution.value, DELIVERY_MEMORY)
        return solution
