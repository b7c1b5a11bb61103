"""The paper's joint optimization by alternating optimization (Algorithm 2; MODEL.md §4).

Per slot: minimize the expected cost J^ over the increment sequences {Delta-mu_k}, the powers p
and the drone position q, subject to the control set, sum p <= P_max, p >= 0, the speed disc and
the area. The three blocks alternate until the relative decrease of J^ over an iteration is below
``tolerance`` or ``max_iterations`` is reached:

1. control (P3): one exact QP per AGV at psi_k(p_k, q), through the shared
   :class:`lawn_env.mpc.OutageAwareMPC` (the compiled exact solver, warm-started);
2. power (P4): Algorithm 1, projected gradient with Armijo backtracking, analytic gradient,
   exact projection onto the budget set, started from equal power;
3. drone (P5/P6): SCA with the linear surrogate of the paper, minimized exactly over the speed
   disc intersected with the area, with the safeguard of MODEL.md §4: a step is accepted only if
   the true J^ does not increase (backtracking toward the current point).

Each block keeps its previous value if its result would increase J^, so the objective trace is
non-increasing by construction (the paper's convergence argument). The AO ends with a control
block at its final (p, q): the last power or drone block moves psi after the last QP, and the
increments sent must be the QP optimum for the (p, q) that is sent with them. Power and drone blocks are
vectorized across AGVs (no per-AGV Python loops); the control block loops over the K solver
workspaces.

Decisions beyond the paper (documented settings, :class:`AOSettings`):

* Armijo condition along the projection arc: ``J(p+) <= J(p) + beta grad'(p+ - p)``, which is
  the paper's ``J(p) - beta rho ||grad||^2`` whenever the projection is inactive, and still
  terminates when it is active (the paper's form can reject every step at the boundary);
* the initial PGD step is ``P_max / ||grad||`` (the paper leaves rho unset), reduced by
  ``1/(1 + rho_hat)`` before the first test, as Algorithm 1 writes it.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Annotated

import numpy as np
import numpy.typing as npt
from pydantic import ConfigDict, Field
from pydantic.dataclasses import dataclass as pydantic_dataclass

from lawn_env import channel
from lawn_env.config import ScenarioConfig
from lawn_env.core import Snapshot
from lawn_env.dynamics import POSITION, PredictionModel
from lawn_env.errors import raises_config_errors
from lawn_env.mpc import DEFAULT_BACKEND, MPCSolution, OutageAwareMPC
from lawn_env.products import matmul

from .optim import linear_argmin_disc_box, project_budget
from .problem import Coefficients, Plan, SlotProblem

__all__ = ["AOSettings", "AOSolver", "PowerObjective", "DroneObjective", "expected_cost", "BLOCKS"]

BLOCKS = ("control", "power", "drone")


@raises_config_errors(noun="setting")
@pydantic_dataclass(frozen=True, config=ConfigDict(extra="forbid", allow_inf_nan=False))
class AOSettings:
    """Settings of the alternating optimization (the paper's symbols where it has them)."""

    max_iterations: Annotated[int, Field(ge=1)] = 20
    """iota_max, AO iterations per slot."""
    tolerance: Annotated[float, Field(ge=0)] = 1e-2
    """epsilon of Algorithm 2: stop when an iteration lowers J^ by less than this fraction. The
    paper gives no value and reports convergence "within a few iterations"; tighter values keep
    lowering J^, slowly, at K more QPs per iteration (docs/experts.md has the sweep)."""
    pgd_max_iterations: Annotated[int, Field(ge=1)] = 5
    """Algorithm 1 iterations per power block (it continues from the current powers at the next
    AO iteration, so the cap bounds the work per pass, not the accuracy of the AO)."""
    pgd_tolerance: Annotated[float, Field(gt=0)] = 1e-6
    """Algorithm 1 stops when ||p - p'|| < pgd_tolerance * P_max."""
    pgd_armijo: Annotated[float, Field(gt=0, lt=1)] = 1e-4
    """beta of the Armijo condition."""
    pgd_backtrack: Annotated[float, Field(gt=0)] = 1.0
    """rho_hat: each backtracking step divides rho by (1 + rho_hat)."""
    pgd_max_backtracks: Annotated[int, Field(ge=1)] = 40
    pgd_restart_equal: bool = False
    """Start Algorithm 1 from equal power at every AO iteration (the literal reading); False starts
    it from the current powers, which are equal power at the first iteration."""
    sca_max_iterations: Annotated[int, Field(ge=1)] = 3
    """SCA iterations per drone block (it continues from the current position at the next AO
    iteration)."""
    sca_tolerance_m: Annotated[float, Field(gt=0)] = 1e-2
    """SCA stops when its step (after the safeguard's halvings) is shorter than this (m)."""
    warm_start: bool = False
    """Start the AO from the previous slot's powers (``snapshot.last_power_w``) instead of equal
    power; the drone starts at q[n-1] either way (the paper leaves the initial point open).
    Off by default: psi is flat near p = 0, so a link whose power collapsed to 0 has a zero
    gradient and Algorithm 1 started there never gives it power again (the AGV then drifts on its
    last acceleration); equal power re-evaluates every link each slot."""
    qp_backend: str = DEFAULT_BACKEND
    """QP backend of the control block (see :mod:`lawn_env.mpc`)."""


class PowerObjective:
    """J^(p) = sum L psi(p)^2 + 2 S psi(p) + W for fixed increments and drone (problem P4), with
    the analytic gradient of Algorithm 1: dJ/dp_k = (2 L_k psi_k + 2 S_k) d psi_k / d p_k."""

    def __init__(self, coef: Coefficients, d2: np.ndarray, link: channel.LinkParams):
        lcoef, scoef, wcoef = coef
        self._l, self._two_l, self._two_s, self._w = lcoef, 2.0 * lcoef, 2.0 * scoef, float(wcoef.sum())
        self._d2 = d2
        self._link = link

    def value(self, p: np.ndarray) -> tuple[float, tuple[np.ndarray, ...]]:
        """(J^, state) where state = (psi, floored powers, outage arguments) feeds :meth:`gradient`."""
        pf = np.maximum(p, channel.POWER_FLOOR_W)
        x = self._link.outage_argument_sq(pf, self._d2)
        psi = self._link.success_at(x)
        return float(matmul(self._l, psi * psi) + matmul(self._two_s, psi)) + self._w, (psi, pf, x)

    def gradient(self, state: tuple[np.ndarray, ...]) -> np.ndarray:
        psi, pf, x = state
        dpsi = self._link.success_power_slope(x, pf)  # reusing the value's x
        grad: np.ndarray = (self._two_l * psi + self._two_s) * dpsi
        return grad


class DroneObjective:
    """J^(q) for fixed increments and powers (problem P5) and its gradient (paper eq. grad_q)."""

    def __init__(self, coef: Coefficients, agv_xy: np.ndarray, power_w: np.ndarray, link: channel.LinkParams):
        self._l, self._s, self._w = coef
        self._agv = agv_xy
        self._power = power_w
        self._link = link

    def value(self, q: np.ndarray) -> float:
        psi = self._link.success_sq(self._power, self._link.distance_sq(q, self._agv))
        return float(((self._l * psi + 2.0 * self._s) * psi + self._w).sum())

    def gradient(self, q: np.ndarray) -> np.ndarray:
        psi, _, dpsi_dq = channel.success_and_gradients(self._power, q, self._agv, self._link)
        grad: np.ndarray = matmul(2.0 * self._l * psi + 2.0 * self._s, dpsi_dq)
        return grad


@dataclass
class _Point:
    """The AO's current point within one slot and what it has counted on the way there."""

    dmu: np.ndarray | None  # (K, N_p, 2); None until the first control block
    power_w: np.ndarray
    drone_position: np.ndarray
    value: float  # J^ at the point
    trace: list[list[float]] = field(default_factory=list)
    iterations: int = 0
    qp_fallbacks: int = 0
    pgd_iterations: int = 0
    sca_iterations: int = 0


@dataclass
class _SlotMemory:
    """The step sizes carried across one slot's AO iterations: the power step's last Barzilai-Borwein
    trial (None: none yet) and the SCA trust region's start."""

    pgd_trial: float | None = None
    sca_t: float = 1.0


class AOSolver:
    """Alternating optimization over (controls, power, drone) for one scenario config."""

    def __init__(self, config: ScenarioConfig, settings: AOSettings | None = None):
        self.config = config
        self.settings = settings or AOSettings()
        self.num_agvs = config.num_agvs
        self.horizon = config.control.horizon
        self.model = PredictionModel.from_config(config)
        self.mpc = OutageAwareMPC.from_config(config, backend=self.settings.qp_backend)
        self.link = channel.LinkParams.from_config(config, planning=True)
        self.power_budget_w = config.power_budget_w
        self._memory = _SlotMemory()

    def reset(self) -> None:
        """Drop warm starts (per episode)."""
        self.mpc.reset()

    def equal_power(self) -> np.ndarray:
        return np.full(self.num_agvs, self.power_budget_w / self.num_agvs)

    # ------------------------------------------------------------------ blocks
    def control_block(self, prob: SlotProblem, power_w: np.ndarray, q: np.ndarray, dmu: np.ndarray | None,
                      current: float) -> tuple[np.ndarray, float, MPCSolution]:
        """P3 at psi(p, q); keeps ``dmu`` if the new solve does not lower J^ (numerical safety)."""
        psi = prob.success(power_w, q)
        sol = self.mpc.solve_prepared(prob.data, psi)
        value = float(sol.value.sum())
        if dmu is None or value <= current:
            return sol.increments, value, sol
        return dmu, current, sol

    def power_objective(self, coef: Coefficients, d2: np.ndarray) -> PowerObjective:
        """J^(p) for fixed increments (coefficients ``coef``) and squared distances ``d2``."""
        return PowerObjective(coef, d2, self.link)

    def drone_objective(self, prob: SlotProblem, coef: Coefficients, power_w: np.ndarray) -> DroneObjective:
        """J^(q) for fixed increments and powers."""
        return DroneObjective(coef, prob.agv_xy, power_w, self.link)

    def power_block(self, coef: Coefficients, d2: np.ndarray, p_current: np.ndarray,
                    current: float) -> tuple[np.ndarray, float, int]:
        """Algorithm 1 (from ``p_current``, or from equal power with ``pgd_restart_equal``);
        returns the better of its result and ``p_current``.

        Trial step: Barzilai-Borwein ``s's / s'y`` from the last two iterates when it is positive,
        else ``P_max / ||grad||`` (the paper leaves the initial rho open); Algorithm 1 then divides
        it by (1 + rho_hat) until the Armijo condition holds.
        """
        s = self.settings
        budget = self.power_budget_w
        grow = 1.0 + s.pgd_backtrack
        armijo = s.pgd_armijo
        objective = self.power_objective(coef, d2)
        p = self.equal_power() if s.pgd_restart_equal else np.array(p_current, dtype=float)
        value, state = objective.value(p)
        grad = objective.gradient(state)
        trial = self._memory.pgd_trial  # the last BB step of this slot, if any
        iterations = 0
        for iterations in range(1, s.pgd_max_iterations + 1):  # noqa: B007 - the count is read after the loop
            gnorm = math.sqrt(float(matmul(grad, grad)))
            if gnorm == 0.0:
                break
            rho = (trial if trial is not None else budget / gnorm) * grow
            accepted = False
            for _ in range(s.pgd_max_backtracks):
                rho /= grow
                p_new = project_budget(p - rho * grad, budget)
                value_new, state_new = objective.value(p_new)
                if value_new <= value + armijo * float(matmul(grad, p_new - p)):
                    accepted = True
                    break
            if not accepted:
                break
            step = p_new - p
            grad_new = objective.gradient(state_new)
            sy = float(matmul(step, grad_new - grad))
            trial = float(matmul(step, step)) / sy if sy > 0 else None
            p, grad, value = p_new, grad_new, value_new
            if math.sqrt(float(matmul(step, step))) < s.pgd_tolerance * budget:
                break
        self._memory.pgd_trial = trial
        if value <= current:
            return p, value, iterations
        return p_current, current, iterations

    def drone_block(self, prob: SlotProblem, coef: Coefficients, power_w: np.ndarray, q_current: np.ndarray,
                    current: float) -> tuple[np.ndarray, float, int]:
        """SCA over the speed disc and the area, with the monotonicity safeguard."""
        s = self.settings
        objective = self.drone_objective(prob, coef, power_w)
        q, value = np.array(q_current, dtype=float), current
        iterations = 0
        # the safeguard's backtracking starts from twice the last accepted fraction (kept across the
        # AO iterations of a slot)
        t_start = self._memory.sca_t
        for iterations in range(1, s.sca_max_iterations + 1):  # noqa: B007 - the count is read after the loop
            grad = objective.gradient(q)
            target = linear_argmin_disc_box(grad, prob.q_prev, prob.reach, prob.area)
            step = target - q
            length = math.hypot(step[0], step[1])
            if length < s.sca_tolerance_m:
                break
            t = t_start
            accepted = False
            while t * length >= s.sca_tolerance_m:
                cand = q + t * step
                cand_value = objective.value(cand)
                if cand_value < value:
                    accepted = True
                    break
                t *= 0.5
            if not accepted:
                break
            q, value = cand, cand_value
            if t * length < 2.0 * s.sca_tolerance_m:
                break
            t_start = min(1.0, 2.0 * t)
        self._memory.sca_t = t_start
        return q, value, iterations

    # ------------------------------------------------------------------ the AO loop
    def plan(self, snapshot: Snapshot) -> Plan:
        """The paper's joint AO over all three blocks (:class:`agents.base.Planner`)."""
        return self.solve(snapshot)

    def solve(self, snapshot: Snapshot, *, blocks: Sequence[str] = BLOCKS, increments: np.ndarray | None = None,
              power_w: np.ndarray | None = None, drone_position: np.ndarray | None = None) -> Plan:
        """Alternate the given ``blocks`` from the initial point and return the plan.

        Blocks not in ``blocks`` stay at their initial values: ``increments`` (required when the
        control block is off), ``power_w`` (default equal power), ``drone_position`` (default
        hover at q[n-1]).
        """
        start = time.perf_counter()
        _check_blocks(blocks, increments)
        prob = SlotProblem(self.mpc, self.link, snapshot, self.config)
        self._memory = _SlotMemory()  # step sizes carried across the AO iterations of this slot
        point = self._initial_point(prob, snapshot, increments, power_w, drone_position)
        self._alternate_until_converged(prob, blocks, point)
        before_final = point.value
        if "control" in blocks and ("power" in blocks or "drone" in blocks):
            # The last power or drone block moved psi after the last QP: end with the control
            # block at the returned (p, q), so the increments sent are that QP's exact optimum
            # (one more QP per AGV; J^ can only fall, the trace stays monotone).
            self._solve_controls(prob, point)
        return _to_plan(prob, point, before_final, start)

    def _initial_point(self, prob: SlotProblem, snapshot: Snapshot, increments: np.ndarray | None,
                       power_w: np.ndarray | None, drone_position: np.ndarray | None) -> _Point:
        """The AO's starting (increments, p, q) and J^ there (infinite until the first QP when the
        increments are left to the control block)."""
        if power_w is not None:
            p = np.asarray(power_w, dtype=float)
        elif self.settings.warm_start and snapshot.last_power_w is not None:
            p = project_budget(np.asarray(snapshot.last_power_w, dtype=float), self.power_budget_w)
        else:
            p = self.equal_power()
        q = prob.q_prev.copy() if drone_position is None else np.asarray(drone_position, dtype=float)
        dmu = None if increments is None else np.asarray(increments, dtype=float)
        value = prob.objective(dmu, p, q) if dmu is not None else math.inf
        return _Point(dmu, p, q, value)

    def _alternate_until_converged(self, prob: SlotProblem, blocks: Sequence[str], point: _Point) -> None:
        """Algorithm 2's loop: block passes until one lowers J^ by less than ``tolerance`` (relative)
        or ``max_iterations`` have run."""
        for iteration in range(1, self.settings.max_iterations + 1):
            point.iterations = iteration
            before = point.value
            point.trace.append(self._run_blocks(prob, blocks, point))
            if math.isfinite(before) and before - point.value <= self.settings.tolerance * abs(before):
                break

    def _run_blocks(self, prob: SlotProblem, blocks: Sequence[str], point: _Point) -> list[float]:
        """One AO iteration: control, power, drone in turn (those in ``blocks``); returns the trace
        row, J^ after each block run (NaN for the others)."""
        row = [math.nan, math.nan, math.nan]
        if "control" in blocks:
            self._solve_controls(prob, point)
            row[0] = point.value
        assert point.dmu is not None  # the first control block ran, or the increments were given
        coef = prob.coefficients(point.dmu)
        if "power" in blocks:
            point.power_w, point.value, its = self.power_block(coef, prob.distance_sq(point.drone_position),
                                                               point.power_w, point.value)
            point.pgd_iterations += its
            row[1] = point.value
        if "drone" in blocks:
            point.drone_position, point.value, its = self.drone_block(prob, coef, point.power_w,
                                                                      point.drone_position, point.value)
            point.sca_iterations += its
            row[2] = point.value
        return row

    def _solve_controls(self, prob: SlotProblem, point: _Point) -> None:
        """The control block at the point's (p, q), counting the QP fallbacks."""
        point.dmu, point.value, sol = self.control_block(prob, point.power_w, point.drone_position, point.dmu,
                                                         point.value)
        point.qp_fallbacks += sol.num_fallbacks


def _check_blocks(blocks: Sequence[str], increments: np.ndarray | None) -> None:
    unknown = [b for b in blocks if b not in BLOCKS]
    if unknown:
        raise ValueError(f"unknown AO blocks {unknown}; valid: {', '.join(BLOCKS)}")
    if "control" not in blocks and increments is None:
        raise ValueError("increments are required when the control block is not optimized")


def _to_plan(prob: SlotProblem, point: _Point, before_final: float, start: float) -> Plan:
    """The AO's result as a :class:`Plan` (``before_final``: J^ before the closing control block)."""
    p, q = point.power_w, point.drone_position
    assert point.dmu is not None  # the control block ran, or the increments were given
    return Plan(
        increments=point.dmu,
        power_w=p,
        drone_position=q,
        objective=point.value,
        objective_trace=np.array(point.trace),
        iterations=point.iterations,
        solve_time_s=time.perf_counter() - start,
        info={
            "qp_fallbacks": point.qp_fallbacks,
            "pgd_iterations": point.pgd_iterations,
            "sca_iterations": point.sca_iterations,
            "success_probability": prob.success(p, q),
            "objective_before_final_qp": before_final,
        },
    )


def expected_cost(snapshot: Snapshot, accel_increments: npt.ArrayLike, power_w: npt.ArrayLike,
                  drone_position: npt.ArrayLike, *, per_agv: bool = False) -> float | np.ndarray:
    """J^_n of MODEL.md §3 for any candidate (increments (K, N_p, 2), powers (K,), drone q[n] (2,)).

    Uses the planners' link model (``channel.ce_aware_planning``); feasibility is not checked.
    """
    config = snapshot.config
    k, n = config.num_agvs, config.control.horizon
    dmu = np.asarray(accel_increments, dtype=float)
    p = np.asarray(power_w, dtype=float)
    q = np.asarray(drone_position, dtype=float)
    if dmu.shape != (k, n, 2):
        raise ValueError(f"accel_increments has shape {dmu.shape}; expected ({k}, {n}, 2)")
    if p.shape != (k,):
        raise ValueError(f"power_w has shape {p.shape}; expected ({k},)")
    if q.shape != (2,):
        raise ValueError(f"drone_position has shape {q.shape}; expected (2,)")
    model = PredictionModel.from_config(config)
    link = channel.LinkParams.from_config(config, planning=True)
    x_aug = np.asarray(snapshot.x_aug, dtype=float)
    r = model.residual(x_aug, np.asarray(snapshot.reference, dtype=float))
    z = dmu.reshape(k, -1)
    fz = matmul(z, model.f.T)
    psi = link.success_sq(p, link.distance_sq(q, x_aug[:, POSITION]))
    e = r + psi[:, None] * fz  # chi - chi_ref with the expected dynamics
    per = np.einsum("ki,ij,kj->k", e, model.q4, e) + np.einsum("ki,ij,kj->k", z, model.q5, z)
    return per if per_agv else float(per.sum())
