"""AGV dynamics, the outage-aware prediction model and its cost (MODEL.md §3).

State x = [x, y, v_x, v_y] (m, m/s), input u = [a_x, a_y] (m/s^2); augmented state
x~ = [x; u[n-1]] in R^6 (:data:`POSITION`, :data:`VELOCITY`, :data:`ACCELERATION` name its
parts) with input Delta-u[n] = u[n] - u[n-1]. Each equation lives once here:

* the transition: :func:`agv_matrices` (A, B); everything else (A~, B~, the simulator's packed
  matrix, the MPC's prediction matrices, the LQR gain, the actuator lag's correction) is built
  from it;
* the control set: :func:`saturate` (compiled; :data:`saturate_increment` over arrays);
* the actuator lag: :func:`lagged_acceleration` (compiled);
* measurement noise: :func:`measure`; the initial state: :func:`initial_state`;
* the stage cost ``e' Q1 e + Delta-u' Q2 Delta-u``: :func:`packed_step_matrices` (the simulator's
  form) and :class:`PredictionModel` (the MPC's horizon form, Q4 and Q5 from the same Q1, Q2).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any, Protocol

import numba
import numpy as np
import numpy.typing as npt
from scipy import linalg

from .products import matmul, solve

__all__ = [
    "ScenarioSettings",
    "agv_matrices",
    "augmented_matrices",
    "terminal_weight",
    "modified_riccati",
    "dare",
    "loss_aware_gain",
    "mean_square_radius",
    "prediction_matrices",
    "horizon_weights",
    "increment_sum_matrix",
    "PredictionModel",
    "PlanningSystem",
    "planning_system",
    "step_augmented",
    "packed_step_matrices",
    "cost_coefficients",
    "saturate",
    "saturate_increment",
    "lagged_acceleration",
    "lag_alpha",
    "initial_state",
    "measure",
    "POSITION",
    "VELOCITY",
    "ACCELERATION",
]

#: The parts of the augmented state x~ (its last axis): position, velocity, previous acceleration.
POSITION, VELOCITY, ACCELERATION = slice(0, 2), slice(2, 4), slice(4, 6)


@numba.njit(cache=True)
def saturate(u_prev: float, du: float, accel_max: float) -> float:  # pragma: no cover - compiled
    """The increment ``du`` clipped so that ``|u[n-1] + du| <= a_max`` (the control set, by saturation)."""
    u = max(u_prev + du, -accel_max)
    u = min(u, accel_max)
    return u - u_prev


@numba.vectorize(["float64(float64, float64, float64)"], cache=True)
def _saturate_dufunc(u_prev: float, du: float, accel_max: float) -> float:  # pragma: no cover - compiled
    value: float = saturate(u_prev, du, accel_max)
    return value


#: :func:`saturate` over arrays (broadcasting, a new array): numpy's ufunc of the compiled loop,
#: which dispatches faster than numba's wrapper.
saturate_increment = _saturate_dufunc.ufunc


def lag_alpha(slot_s: float, lag_s: float) -> float:
    """The actuator lag's alpha = exp(-slot / lag) of :func:`lagged_acceleration`; -1.0 without a lag
    (``lag_s`` = 0), which the slot kernel reads as "no lag"."""
    return float(np.exp(-slot_s / lag_s)) if lag_s > 0 else -1.0


@numba.njit(cache=True)
def lagged_acceleration(applied: float, commanded: float, lag_alpha: float) -> float:  # pragma: no cover
    """The acceleration an AGV applies next under actuator lag (MODEL.md §7): a first-order lag
    toward the commanded one, ``alpha a + (1 - alpha) u`` with ``alpha = exp(-slot / lag)``."""
    return lag_alpha * applied + (1.0 - lag_alpha) * commanded


def initial_state(reference_start: np.ndarray, offsets: np.ndarray, area_lo: np.ndarray,
                  area_hi: np.ndarray) -> np.ndarray:
    """Augmented AGV states at slot 0: the reference start position plus ``offsets`` (kept in
    the area), the reference velocity, zero previous acceleration. (..., K, 6) from the
    reference's first slot (..., K, 6) and offsets (..., K, 2)."""
    x_aug = np.zeros(reference_start.shape)
    x_aug[..., POSITION] = np.clip(reference_start[..., POSITION] + offsets, area_lo, area_hi)
    x_aug[..., VELOCITY] = reference_start[..., VELOCITY]
    return x_aug


def measure(x_aug: np.ndarray, tracking_error: np.ndarray, position_noise: np.ndarray,
            velocity_noise: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """What the policies observe under measurement noise (..., K, 2) on positions and velocities:
    the state and the tracking error, both with the same noise."""
    noise = np.zeros_like(x_aug)
    noise[..., POSITION] = position_noise
    noise[..., VELOCITY] = velocity_noise
    return x_aug + noise, tracking_error + noise


class ScenarioSettings(Protocol):
    """What this module reads of a scenario's config (a :class:`lawn_env.config.ScenarioConfig`,
    which validates itself with this module: a protocol, so the two do not import each other)."""

    @property
    def slot_s(self) -> float: ...

    @property
    def control(self) -> Any: ...  # horizon, q1_diag, q2_diag

    @property
    def disturbance(self) -> Any: ...  # control_period_slots, period_aware_planning


def agv_matrices(slot_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Constant-acceleration model x[n+1] = A x[n] + B u[n] (paper, Section II-B)."""
    dt = float(slot_s)
    a = np.eye(4)
    a[0, 2] = a[1, 3] = dt
    b = np.array([[dt * dt / 2, 0.0], [0.0, dt * dt / 2], [dt, 0.0], [0.0, dt]])
    return a, b


def augmented_matrices(slot_s: float) -> tuple[np.ndarray, np.ndarray]:
    """A~ = [[A, B], [0, I2]], B~ = [B; I2] for x~[n+1] = A~ x~[n] + B~ Delta-u[n]."""
    a, b = agv_matrices(slot_s)
    a_aug = np.block([[a, b], [np.zeros((2, 4)), np.eye(2)]])
    b_aug = np.vstack([b, np.eye(2)])
    return a_aug, b_aug


def lag_matrices(slot_s: float, lag_alpha: float) -> tuple[np.ndarray, np.ndarray]:
    """The augmented model with the actuator lag of MODEL.md §7 (:func:`lagged_acceleration`) for a
    planner: the state ``[p, v, u[n-1], a[n-1]]`` (8 entries: x~ and the acceleration the AGV applied
    in the slot before), the input Delta-u. The AGV commands ``u = u[n-1] + Delta-u``, applies
    ``a = alpha a[n-1] + (1 - alpha) u`` and moves with it, as the simulator's slot does (its
    acceleration columns of A~ take ``a`` in place of ``u``). Returns (A (8, 8), B (8, 2))."""
    a_aug, _ = augmented_matrices(slot_s)
    effect = a_aug[0:4, 4:6]  # how an acceleration moves position and velocity over a slot
    eye = np.eye(2)
    # the lag's coefficients on the applied and the commanded acceleration, from the simulator's law
    held, taken = lagged_acceleration(1.0, 0.0, lag_alpha), lagged_acceleration(0.0, 1.0, lag_alpha)
    a8, b8 = np.zeros((8, 8)), np.zeros((8, 2))
    a8[0:4, 0:4] = a_aug[0:4, 0:4]
    a8[0:4, 4:6], a8[0:4, 6:8], b8[0:4] = taken * effect, held * effect, taken * effect
    a8[4:6, 4:6], b8[4:6] = eye, eye
    a8[6:8, 4:6], a8[6:8, 6:8], b8[6:8] = taken * eye, held * eye, taken * eye
    return a8, b8


def modified_riccati(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray, success: float = 1.0,
                     start: np.ndarray | None = None) -> np.ndarray:
    """The cost-to-go S of the linear-quadratic regulator whose every command arrives with probability
    ``success`` = psi, a lost one being seen and replanned (Bernoulli actuation loss with
    acknowledgements; Schenato, Sinopoli, Franceschetti, Poolla, Sastry, Proc. IEEE 2007):

        S = A'SA + Q - psi A'SB (R + B'SB)^-1 B'SA.

    At psi = 1 it is the discrete algebraic Riccati equation (:func:`dare`); below, value iteration
    from ``start`` (default: the DARE's solution, a lower bound: the iterates rise monotonically to the
    solution) until the largest change is 1e-12 of the largest entry. Raises ``ValueError`` where no
    finite solution exists (psi at or below the critical arrival probability of ``a``)."""
    if not 0.0 < success <= 1.0:
        raise ValueError(f"success={success!r}: the arrival probability must lie in (0, 1]")
    s = dare(a, b, q, r) if start is None else np.array(start, dtype=float)
    if not np.all(np.isfinite(s)):
        raise ValueError("the discrete Riccati equation has no finite solution for these weights")
    if success < 1.0 or start is not None:
        with np.errstate(over="ignore", invalid="ignore"):  # a diverging iteration stops at the check below
            settled = _value_iteration(a, b, q, r, success, s)
        if settled is None:
            raise ValueError(f"success={success!r}: the modified Riccati equation does not converge (at or below "
                             "the critical arrival probability of these dynamics)")
        s = settled
    symmetric: np.ndarray = 0.5 * (s + s.T)
    return symmetric


def _value_iteration(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray, success: float,
                     s: np.ndarray) -> np.ndarray | None:
    """:func:`modified_riccati`'s iteration from ``s``; None when it diverges."""
    for _ in range(1_000_000):
        gain = loss_aware_gain(a, b, r, s)
        nxt = q + matmul(matmul(a.T, s), a) - success * matmul(matmul(matmul(a.T, s), b), gain)
        nxt = 0.5 * (nxt + nxt.T)
        scale = np.abs(nxt).max()
        if not np.isfinite(scale):
            return None
        done = np.abs(nxt - s).max() <= 1e-12 * scale
        s = nxt
        if done:
            return s
    return None


def loss_aware_gain(a: np.ndarray, b: np.ndarray, r: np.ndarray, s: np.ndarray) -> np.ndarray:
    """The state feedback ``L = (R + B'SB)^-1 B'SA`` of the cost-to-go ``s`` (the command is -L x):
    the LQR gain at the DARE's S, the loss-aware gain at the modified Riccati equation's."""
    bts = matmul(b.T, s)
    return solve(r + matmul(bts, b), matmul(bts, a))


def dare(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray, max_iterations: int = 64) -> np.ndarray:
    """The stabilizing solution X of the discrete algebraic Riccati equation
    ``X = A'XA - A'XB (R + B'XB)^-1 B'XA + Q`` by the structure-preserving doubling algorithm (Chu, Fan,
    Lin and Wang, 2004): ``A_0 = A``, ``G_0 = B R^-1 B'``, ``H_0 = Q``, ``W_k = I + G_k H_k``,
    ``A_{k+1} = A_k W_k^-1 A_k``, ``G_{k+1} = G_k + A_k W_k^-1 G_k A_k'``, ``H_{k+1} = H_k + A_k' H_k W_k^-1 A_k``;
    ``H_k`` converges quadratically to X. Every product and solve in one fixed order
    (:mod:`lawn_env.products`), so X is the same to the last bit on every machine, which scipy's
    ``solve_discrete_are`` (LAPACK on the CPU's BLAS kernel) is not; scipy is the tests' oracle. Raises
    ``ValueError`` when the iteration does not settle (no stabilizing solution)."""
    n = a.shape[0]
    hk: np.ndarray
    ak, gk, hk = np.array(a, dtype=float), matmul(b, solve(r, b.T)), np.array(q, dtype=float)
    for _ in range(max_iterations):
        w = np.eye(n) + matmul(gk, hk)
        w_a, w_g = solve(w, ak), solve(w, gk)
        h_next = hk + matmul(matmul(ak.T, hk), w_a)
        g_next = gk + matmul(matmul(ak, w_g), ak.T)
        ak = matmul(ak, w_a)
        change = np.abs(h_next - hk).max()
        hk, gk = 0.5 * (h_next + h_next.T), 0.5 * (g_next + g_next.T)
        if not np.all(np.isfinite(hk)):
            break
        if change <= 1e-15 * np.abs(hk).max():
            return hk
    raise ValueError("the discrete Riccati equation has no stabilizing solution for these weights")


def mean_square_radius(a: np.ndarray, b: np.ndarray, gain: np.ndarray, success: float) -> float:
    """The spectral radius of the second-moment map of ``x+ = (A - delta B L) x``, delta ~ Bernoulli(psi):
    ``psi (A-BL)⊗(A-BL) + (1-psi) A⊗A`` (the Kronecker test). Below 1: mean-square stable."""
    closed = a - b @ gain
    moment = success * np.kron(closed, closed) + (1.0 - success) * np.kron(a, a)
    return float(np.max(np.abs(np.linalg.eigvals(moment))))


def terminal_weight(a_aug: np.ndarray, b_aug: np.ndarray, q1: np.ndarray, q2: np.ndarray,
                    success: float = 1.0) -> np.ndarray:
    """Q3: the stabilizing solution of the discrete algebraic Riccati equation (paper eq. for Q3)

    Q3 = Q1 + A~' Q3 A~ - A~' Q3 B~ (Q2 + B~' Q3 B~)^-1 B~' Q3 A~;

    with ``success`` = psi < 1 the modified Riccati equation's (:func:`modified_riccati`): the
    certainty-equivalent MPC's ``terminal_success`` refinement (docs/experts.md)."""
    if not 0.0 < success <= 1.0:
        raise ValueError(f"success={success!r}: the terminal weight's success probability must lie in (0, 1]")
    return modified_riccati(a_aug, b_aug, q1, q2, success)


def prediction_matrices(a_aug: np.ndarray, b_aug: np.ndarray, horizon: int) -> tuple[np.ndarray, np.ndarray]:
    """Condensed prediction chi = C x~ + psi F Delta-mu over i = 0..N_p.

    C = [I; A~; ...; A~^N_p] (6(N_p+1) x 6); F block lower-triangular (6(N_p+1) x 2 N_p) with
    block (i, j) = A~^(i-1-j) B~ for j < i, zero first block row.
    """
    nx, nu = b_aug.shape
    powers = [np.eye(nx)]
    for _ in range(horizon):
        powers.append(matmul(a_aug, powers[-1]))
    c = np.vstack(powers)
    f = np.zeros((nx * (horizon + 1), nu * horizon))
    for i in range(1, horizon + 1):
        for j in range(i):
            f[nx * i : nx * (i + 1), nu * j : nu * (j + 1)] = matmul(powers[i - 1 - j], b_aug)
    return c, f


def horizon_weights(q1: np.ndarray, q2: np.ndarray, q3: np.ndarray, horizon: int) -> tuple[np.ndarray, np.ndarray]:
    """Q4 = diag(Q1 x N_p, Q3), Q5 = diag(Q2 x N_p)."""
    q4 = linalg.block_diag(*([q1] * horizon + [q3]))
    q5 = linalg.block_diag(*([q2] * horizon))
    return q4, q5


def increment_sum_matrix(horizon: int) -> np.ndarray:
    """T with (T Delta-mu)_i = sum_{j<=i} Delta-u_j per axis, so u_i = u[n-1] + (T Delta-mu)_i."""
    return np.kron(np.tril(np.ones((horizon, horizon))), np.eye(2))


def command_mask(slot: int, horizon: int, period: int) -> np.ndarray:
    """Which of the horizon's increments can be non-zero (MODEL.md §7, move blocking): with commands
    sent every ``period`` slots (at slots n with n % period == 0), the increment planned for slot
    ``slot + i`` is True only at those slots; in between the AGV holds its acceleration. (horizon,) bool."""
    if period == 1:
        return np.ones(horizon, dtype=bool)
    sends: np.ndarray = (slot + np.arange(horizon)) % period == 0
    return sends


def planning_period(config: ScenarioSettings) -> int:
    """The control period the planners plan with: ``disturbance.control_period_slots`` when
    ``disturbance.period_aware_planning`` (the default), else 1 (the unaware ablation)."""
    d = config.disturbance
    return int(d.control_period_slots) if d.period_aware_planning else 1


@dataclass(frozen=True, eq=False)
class PredictionModel:
    """Everything the outage-aware MPC needs, built once per (slot, horizon, Q1, Q2).

    Use :meth:`from_config`; instances are cached by those values (``key``) and shared (the arrays
    are read-only).
    """

    slot_s: float
    horizon: int
    a_aug: np.ndarray
    b_aug: np.ndarray
    q1: np.ndarray
    q2: np.ndarray
    q3: np.ndarray
    c: np.ndarray
    f: np.ndarray
    q4: np.ndarray
    q5: np.ndarray
    ftq4f: np.ndarray  # F' Q4 F, (2N_p, 2N_p)
    ftq4: np.ndarray  # F' Q4, (2N_p, 6(N_p+1))
    increment_sum: np.ndarray  # T, (2N_p, 2N_p)
    q1_tiled: np.ndarray | None  # diag(Q1) repeated N_p times: Q4's diagonal blocks, (6 N_p,); None: others
    # (slot_s, horizon, q1_diag, q2_diag[, terminal_success, lag_alpha]): what it is built from, its cache key
    key: tuple[Any, ...]

    @classmethod
    def from_config(cls, config: ScenarioSettings, terminal_success: float = 1.0, lag: bool = False) -> PredictionModel:
        """The model of ``config``; ``terminal_success`` < 1 takes the terminal weight of the modified
        Riccati equation at that success probability (:func:`terminal_weight`); ``lag`` predicts
        with the config's actuator lag (:func:`lag_matrices`; the state then has 8 entries, x~ and
        the applied acceleration), where it has one."""
        ctl = config.control
        alpha = lag_alpha(float(config.slot_s), float(config.disturbance.actuator_lag_s)) if lag else -1.0
        return _build_model(float(config.slot_s), int(ctl.horizon), tuple(ctl.q1_diag), tuple(ctl.q2_diag),
                            float(terminal_success), alpha)

    @property
    def state_dim(self) -> int:
        """Entries of the state the model predicts from: 6 (x~), 8 with the actuator lag (x~ and the
        applied acceleration)."""
        return int(self.c.shape[1])

    @classmethod
    def from_key(cls, key: tuple[Any, ...]) -> PredictionModel:
        """The model built from :attr:`key`'s values (slot_s, horizon, q1_diag, q2_diag[, terminal_success,
        lag_alpha])."""
        return _build_model(*key)

    @property
    def num_inputs(self) -> int:
        return 2 * self.horizon

    @functools.cached_property
    def lqr_gain(self) -> np.ndarray:
        """The infinite-horizon gain of the DARE that gives Q3: ``(Q2 + B~'Q3B~)^-1 B~'Q3A~`` (2 x 6):
        the LQR baseline's (``agents.tracking``) and the RL interface's ``increment_anchor="lqr"``."""
        b, a, q3 = self.b_aug, self.a_aug, self.q3
        return loss_aware_gain(a, b, self.q2, q3)

    def residual(self, x_aug: np.ndarray, chi_ref: np.ndarray) -> np.ndarray:
        """r = C x~ - chi_ref per AGV: (..., K, 6) and (..., K, N_p+1, 6) -> (..., K, 6(N_p+1)) (one
        2-D product over all leading axes: numpy's stacked (B, K, 6) @ (6, m) is several times slower)."""
        lead = x_aug.shape[:-1]
        flat = matmul(np.reshape(x_aug, (-1, x_aug.shape[-1])), self.c.T)
        return flat.reshape((*lead, -1)) - chi_ref.reshape((*lead, -1))

    def cost_to_go(self, r: np.ndarray) -> np.ndarray:
        """r' Q4 r for residuals r (..., 6(N_p+1)): Q4 = diag(Q1 x N_p, Q3) with Q1 diagonal, so the
        first N_p blocks are a weighted sum of squares and only the terminal block is a 6 x 6 form
        (a model whose stage weights are not Q1's, ``q1_tiled`` None: the full form)."""
        cost: np.ndarray
        if self.q1_tiled is None:
            cost = (matmul(r, self.q4) * r).sum(axis=-1)
            return cost
        head, tail = r[..., :-6], r[..., -6:]
        cost = matmul(head * head, self.q1_tiled) + (matmul(tail, self.q3) * tail).sum(axis=-1)
        return cost

    def predict(self, x_aug: np.ndarray, dmu: np.ndarray, psi: npt.ArrayLike) -> np.ndarray:
        """Expected predicted states chi = C x~ + psi F Delta-mu, (K, N_p+1, 6)."""
        k = x_aug.shape[0]
        psi = np.broadcast_to(np.asarray(psi, dtype=float), (k,))
        chi = matmul(x_aug, self.c.T) + psi[:, None] * matmul(dmu.reshape(k, -1), self.f.T)
        windows: np.ndarray = chi.reshape(k, self.horizon + 1, -1)
        return windows


@functools.lru_cache(maxsize=32)
def _build_model(slot_s: float, horizon: int, q1_diag: tuple[float, ...], q2_diag: tuple[float, ...],
                 terminal_success: float = 1.0, lag_alpha: float = -1.0) -> PredictionModel:
    a_aug, b_aug = augmented_matrices(slot_s)
    q1 = np.diag(np.asarray(q1_diag, dtype=float))
    q2 = np.diag(np.asarray(q2_diag, dtype=float))
    q3 = terminal_weight(a_aug, b_aug, q1, q2, terminal_success)
    if lag_alpha >= 0.0:  # predict the 8-state of lag_matrices, weigh its first six entries (x~)
        a8, b8 = lag_matrices(slot_s, lag_alpha)
        c8, f8 = prediction_matrices(a8, b8, horizon)
        keep = (np.arange(8 * (horizon + 1)) % 8) < 6
        c, f = c8[keep], f8[keep]
    else:
        c, f = prediction_matrices(a_aug, b_aug, horizon)
    q4, q5 = horizon_weights(q1, q2, q3, horizon)
    ftq4 = matmul(f.T, q4)
    arrays = {
        "a_aug": a_aug, "b_aug": b_aug, "q1": q1, "q2": q2, "q3": q3, "c": c, "f": f, "q4": q4, "q5": q5,
        "ftq4f": matmul(ftq4, f), "ftq4": ftq4, "increment_sum": increment_sum_matrix(horizon),
        "q1_tiled": np.tile(np.asarray(q1_diag, dtype=float), horizon),
    }
    for arr in arrays.values():
        arr.setflags(write=False)
    extra = (terminal_success, lag_alpha) if (terminal_success, lag_alpha) != (1.0, -1.0) else ()
    key = (slot_s, horizon, q1_diag, q2_diag, *extra)
    return PredictionModel(slot_s=slot_s, horizon=horizon, key=key, **arrays)


@dataclass(frozen=True, eq=False)
class PlanningSystem:
    """The system a loss-aware tail (:mod:`lawn_env.tail`) plans over, built once per (slot, horizon, Q1,
    Q2, period, lag): the transition ``a``, ``b`` of the augmented AGV (x~, 6 states) or, with an
    actuator lag (``lag_alpha`` >= 0, :func:`lag_alpha`), of the lag's 8-state (x~ and the applied
    acceleration; :func:`lag_matrices`), the weights ``q`` (Q1 on x~ alone) and ``r`` (Q2), and its
    prediction matrices ``c``, ``f`` over the horizon (:func:`prediction_matrices`). Use
    :meth:`from_config` or :func:`planning_system`; instances are cached by ``key`` and shared (the
    arrays are read-only)."""

    slot_s: float
    horizon: int
    period: int
    a: np.ndarray
    b: np.ndarray
    q: np.ndarray
    r: np.ndarray
    c: np.ndarray
    f: np.ndarray
    # (slot_s, horizon, q1_diag, q2_diag, period, lag_alpha): what it is built from, its cache key
    key: tuple[Any, ...]

    @classmethod
    def from_config(cls, config: ScenarioSettings, lag: bool = False) -> PlanningSystem:
        """The system of ``config``'s AGVs with the control period the planners know
        (:func:`planning_period`), over the config's horizon or, where the period is longer, over one
        that holds the next command and one after it; ``lag`` predicts with the config's actuator lag,
        where it has one."""
        ctl = config.control
        alpha = lag_alpha(float(config.slot_s), float(config.disturbance.actuator_lag_s)) if lag else -1.0
        period = planning_period(config)
        horizon = max(int(ctl.horizon), period + 1)  # the next command and one after it inside the horizon
        return planning_system(float(config.slot_s), horizon, tuple(ctl.q1_diag), tuple(ctl.q2_diag), period, alpha)

    @property
    def state_dim(self) -> int:
        """Entries of the state: 6 (x~), 8 with the actuator lag (x~ and the applied acceleration)."""
        return int(self.a.shape[0])


@functools.lru_cache(maxsize=16)
def planning_system(slot_s: float, horizon: int, q1_diag: tuple[float, ...], q2_diag: tuple[float, ...],
                    period: int, alpha: float = -1.0) -> PlanningSystem:
    """The shared :class:`PlanningSystem` of these values (``alpha`` >= 0: with the actuator lag)."""
    a, b = lag_matrices(slot_s, alpha) if alpha >= 0.0 else augmented_matrices(slot_s)
    n = a.shape[0]
    q = np.zeros((n, n))
    q[:6, :6] = np.diag(np.asarray(q1_diag, dtype=float))
    r = np.diag(np.asarray(q2_diag, dtype=float))
    c, f = prediction_matrices(a, b, int(horizon))
    for arr in (a, b, q, r, c, f):
        arr.setflags(write=False)
    return PlanningSystem(slot_s=float(slot_s), horizon=int(horizon), period=int(period), a=a, b=b, q=q, r=r, c=c,
                          f=f, key=(slot_s, horizon, q1_diag, q2_diag, period, alpha))


def step_augmented(x_aug: np.ndarray, du: np.ndarray, a_aug: np.ndarray, b_aug: np.ndarray) -> np.ndarray:
    """x~[n+1] = A~ x~[n] + B~ Delta-u, batched: (K, 6), (K, 2) -> (K, 6).

    A lost command is ``du = 0`` (the AGV keeps u[n-1]; MODEL.md §3).
    """
    x_next: np.ndarray = matmul(x_aug, a_aug.T) + matmul(du, b_aug.T)
    return x_next


def packed_step_matrices(a_aug: np.ndarray, b_aug: np.ndarray, q1_diag: npt.ArrayLike,
                         q2_diag: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """The transition and the stage cost on the packed row [x~, Delta-u] (8 entries), for the
    simulator's hot path: ``[x~, du] @ T = [A~ x~ + B~ du, du]`` and, with ``e`` the packed
    error ``[x~ - x~_ref, du]``, ``(e * e) @ W = [e' Q1 e, du' Q2 du]``. Built from the same
    A~, B~, Q1, Q2 as :func:`step_augmented` and the MPC's weights.
    """
    t = np.zeros((8, 8))
    t[0:6, 0:6] = a_aug.T
    t[6:8, 0:6] = b_aug.T
    t[6:8, 6:8] = np.eye(2)
    w = np.zeros((8, 2))
    w[0:6, 0] = q1_diag
    w[6:8, 1] = q2_diag
    return t, w


def cost_coefficients(model: PredictionModel, linear: np.ndarray, constant: np.ndarray,
                      dmu: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """L, S, W from the slot's precomputed ``linear`` = F'Q4 r (K, 2N_p) and ``constant`` =
    r'Q4 r (K,) (see :meth:`lawn_env.mpc.OutageAwareMPC.prepare`); the one implementation of the
    coefficients of P4. The envelope derivative of the QP's value in psi is ``2 psi L + 2 S``.
    ``dmu`` (..., K, N_p, 2) may carry leading axes of its own (one per psi value of a table)."""
    z = dmu.reshape((*dmu.shape[:-2], -1))
    lcoef = (matmul(z, model.ftq4f) * z).sum(axis=-1)
    scoef = (linear * z).sum(axis=-1)
    wcoef = (matmul(z, model.q5) * z).sum(axis=-1) + constant
    return lcoef, scoef, wcoef
