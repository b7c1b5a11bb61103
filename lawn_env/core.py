"""The one simulation core every environment runs: B scenarios of one config at once.

* :class:`SimParams`: everything fixed by the config (links, packed matrices, the area, the fixed
  path set's reference table, the disturbance mode), built once, frozen.
* :class:`SimState`: the episode state of B scenarios as plain arrays with a leading batch axis
  (augmented AGV states, drone positions, slots, references, the last slot's links, the episode's
  running sums for the metrics of MODEL.md §6).
* :func:`draw_slot`: a slot's randomness for B scenarios from one generator, in one documented
  order; :func:`reset` (new episodes for chosen rows, each drawing from its own generator) and
  :func:`step` (one slot of every scenario: ``step(params, state, decisions, draws)`` returns the
  new state and the slot's record, its arguments untouched).
* :class:`Simulation`: the params and the state of B scenarios together, for the environments:
  the single environments and the PettingZoo env are its B = 1 views, the native vector envs its
  B = N views; :meth:`Simulation.row` is one scenario's state as single-scenario arrays.

The slot kernel composes the equations of :mod:`lawn_env.channel` (the link) and
:mod:`lawn_env.dynamics` (the control set, the transition, the lag, the measurement) and holds
none of its own. It knows nothing about action or observation encodings; the environments do
(:mod:`lawn_env.spaces`, :mod:`lawn_env.interface`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any, NamedTuple

import numba
import numpy as np

from . import channel, drone, dynamics, references
from .config import DisturbanceConfig, ScenarioConfig
from .dynamics import POSITION, PredictionModel, initial_state, measure, packed_step_matrices
from .products import product_into

# the first columns of dynamics.POSITION / VELOCITY / ACCELERATION in x~, as integers the kernels can index with
_POS0, _VEL0, _ACCEL0 = dynamics.POSITION.start, dynamics.VELOCITY.start, dynamics.ACCELERATION.start

__all__ = ["SimParams", "SimState", "SlotDraws", "SlotRecord", "Decisions", "Snapshot", "Simulation", "ScenarioView",
           "Trail", "draw_slot", "reset", "step", "step_rows", "episode_metrics", "control_costs", "link_outage",
           "buffer_queue", "later_increments",
           "link_success",
           "SLOT_CONSTANTS", "TOTALS", "DIVERGENCE_DISTANCE_M"]


# ---------------------------------------------------------------------- the slot kernel
# It composes the equations of channel.py and dynamics.py for B scenarios at once; it holds none.
def link_outage(x_aug: np.ndarray, drone_xy: np.ndarray, power_w: np.ndarray,
                link: channel.LinkParams) -> tuple[np.ndarray, np.ndarray]:
    """The outage argument x (Prop. 1) and the outage probability of the links from the drone at
    ``drone_xy`` (..., 2) to the AGVs (x_aug (..., K, 6)) with powers (..., K)."""
    x = link.outage_argument_sq(power_w, link.distance_sq(drone_xy[..., None, :], x_aug[..., POSITION]))
    return x, link.outage_at(x)


def link_success(x_aug: np.ndarray, drone_xy: np.ndarray, power_w: np.ndarray, link: channel.LinkParams) -> np.ndarray:
    """The success probability psi of the links from the drone at ``drone_xy`` (..., 2) to the AGVs
    (x_aug (..., K, 6)) with powers (..., K): the planners' psi when ``link`` is their link model
    (``LinkParams.from_config(config, planning=True)``)."""
    return link.success_sq(power_w, link.distance_sq(drone_xy[..., None, :], x_aug[..., POSITION]))


#: The scalars the slot kernel reads, by name (a record: it passes into compiled code as cheaply
#: as an array): the actuator lag's alpha (-1: no lag), the acceleration bound, and the true
#: link's H^2, c_d, c_ce (:attr:`lawn_env.channel.LinkParams.coefficients`) and m.
SLOT_CONSTANTS = np.dtype([("lag_alpha", "f8"), ("accel_max", "f8"), ("altitude_sq", "f8"), ("c_d", "f8"),
                           ("c_ce", "f8"), ("m", "f8")])


class Packed(NamedTuple):
    """The packed matrices of :func:`lawn_env.dynamics.packed_step_matrices` and A~'s
    acceleration columns (the actuator lag's correction)."""

    step_t: np.ndarray
    cost_w: np.ndarray
    accel_effect_t: np.ndarray


def _array(dtype, ndim: int, out: bool = False, layout: str = "A") -> numba.types.Array:
    """An argument type of the slot kernel: inputs read-only in any layout (a step's states are
    views of the last step's rows), the parameters' matrices and the outputs C-contiguous."""
    return numba.types.Array(dtype, ndim, "C" if out else layout, readonly=not out)


class SlotInputs(NamedTuple):
    """What one slot reads: the state, the decisions and the draws of B scenarios (see :func:`_slot`)."""

    x_aug: np.ndarray  # (B, K, 6)
    increment: np.ndarray  # (B, K, 2)
    send: np.ndarray  # (B,) or (1,): whether the slot sends its commands
    power: np.ndarray  # (B, K)
    drone_next: np.ndarray  # (B, 2)
    fading: np.ndarray  # (B, K)
    reference: np.ndarray  # (B, K, T, 6)
    slot: np.ndarray  # (B,)
    applied: np.ndarray  # (B, K, 2): the applied acceleration (actuator lag)
    process_position: np.ndarray  # (B, K, 2), or (0, 0, 2) without process noise
    process_velocity: np.ndarray
    drone_prev: np.ndarray  # (B, 2)
    totals: np.ndarray  # (B, 5 + 3K)
    plan: np.ndarray  # (B, K, L, 2): the later increments each packet carries (buffered actuator), L = N_p - 1
    buffer: np.ndarray  # (B, K, L, 2): the AGVs' buffers; (B, K, 0, 2) under the hold actuator
    buffer_age: np.ndarray  # (B, K): how many of the buffer's increments have been played (L: spent)


class SlotOutputs(NamedTuple):
    """What one slot writes, new arrays the caller allocates (a compiled function's returned arrays
    cost more to hand back)."""

    rows: np.ndarray  # (2, B, K, 8): [x~[n+1], du applied] and [x~[n+1] - x~_ref[n+1], du]
    terms: np.ndarray  # (B, K, 2): e' Q1 e, du' Q2 du
    delivered: np.ndarray  # (B, K) bool
    outage: np.ndarray  # (B, K)
    applied_next: np.ndarray  # (B, K, 2), under lag
    costs: np.ndarray  # (B, 3)
    totals_next: np.ndarray  # (B, 5 + 3K)
    buffer_next: np.ndarray  # (B, K, L, 2)
    buffer_age_next: np.ndarray  # (B, K)


_F, _B, _I = numba.types.float64, numba.types.boolean, numba.types.int64
_C = numba.types.Array(numba.from_dtype(SLOT_CONSTANTS), 1, "C", readonly=True)
#: The slot kernel's one signature: every caller (single, parallel and vector envs; fixed and random
#: paths; any role) converts to it, so the kernel compiles once instead of once per argument layout.
#: The records cross as plain tuples (numba's dispatcher types a plain tuple in C, a NamedTuple in
#: Python, about 2 us more per call) and are named on entry.
_SLOT_SIGNATURE = numba.types.none(
    numba.types.Tuple([_array(_F, 3), _array(_F, 3), _array(_B, 1), _array(_F, 2), _array(_F, 2), _array(_F, 2),
                       _array(_F, 4), _array(_I, 1), _array(_F, 3), _array(_F, 3), _array(_F, 3), _array(_F, 2),
                       _array(_F, 2), _array(_F, 4), _array(_F, 4), _array(_I, 2)]),
    numba.types.Tuple([_array(_F, 2, layout="C")] * 3), _C,
    numba.types.Tuple([_array(_F, 4, out=True), _array(_F, 3, out=True), _array(_B, 2, out=True),
                       _array(_F, 2, out=True), _array(_F, 3, out=True), _array(_F, 2, out=True),
                       _array(_F, 2, out=True), _array(_F, 4, out=True), _array(_I, 2, out=True)]))


@numba.njit(cache=True, inline="always")
def _links(inp, c, out, rows):  # pragma: no cover - compiled
    """Step 1: per link, the outage argument at the drone's next position, the outage probability,
    the delivery, and the packed row [x~, du applied] with du saturated: the command where it arrives;
    where none arrives (lost, or a slot without commands) zero under the hold actuator and the
    buffer's next increment under the buffered one (:func:`_played`)."""
    x_aug, increment, send, power, drone_next, fading = (inp.x_aug, inp.increment, inp.send, inp.power,
                                                         inp.drone_next, inp.fading)
    outage, delivered = out.outage, out.delivered
    k = x_aug.shape[1]
    buffered = inp.buffer.shape[2] > 0
    altitude_sq, c_d, c_ce, m, accel_max = c.altitude_sq, c.c_d, c.c_ce, c.m, c.accel_max
    for b in range(x_aug.shape[0]):
        sending = send[b % send.shape[0]]
        for i in range(k):
            r = b * k + i
            d2 = channel.link_distance_sq(x_aug[b, i, _POS0] - drone_next[b, 0],
                                          x_aug[b, i, _POS0 + 1] - drone_next[b, 1], altitude_sq)
            x = channel.link_argument(d2, power[b, i], c_d, c_ce)
            outage[b, i] = channel.outage_law(m, x, channel.OUTAGE)
            ok = channel.command_delivered(fading[b, i], x)
            delivered[b, i] = ok
            for j in range(6):
                rows[r, j] = x_aug[b, i, j]
            if buffered:
                for a in range(2):
                    du = increment[b, i, a] if sending and ok else _played(inp.buffer, inp.buffer_age, b, i, a)
                    rows[r, 6 + a] = dynamics.saturate(x_aug[b, i, _ACCEL0 + a], du, accel_max)
                continue
            for a in range(2):
                du = dynamics.saturate(x_aug[b, i, _ACCEL0 + a], increment[b, i, a], accel_max) if sending else 0.0
                rows[r, 6 + a] = du * (1.0 if ok else 0.0)


@numba.njit(cache=True, inline="always")
def _played(buffer, age, b, i, a):  # pragma: no cover - compiled
    """The increment AGV i of scenario b plays without a packet under the buffered actuator: its
    buffer's next one, zero (a hold) once the buffer is spent."""
    j = age[b, i]
    return buffer[b, i, j, a] if j < buffer.shape[2] else 0.0


@numba.njit(cache=True, inline="always")
def _buffers(inp, out):  # pragma: no cover - compiled
    """Step 1b (buffered actuator): a delivered packet replaces the AGV's buffer with the later
    increments it carries (none played yet); otherwise the buffer advances by the one it played."""
    buffer, age, plan, send, delivered = inp.buffer, inp.buffer_age, inp.plan, inp.send, out.delivered
    length = buffer.shape[2]
    for b in range(buffer.shape[0]):
        sending = send[b % send.shape[0]]
        for i in range(buffer.shape[1]):
            fresh = sending and delivered[b, i]
            out.buffer_age_next[b, i] = 0 if fresh else min(age[b, i] + 1, length)
            for j in range(length):
                for a in range(2):
                    out.buffer_next[b, i, j, a] = plan[b, i, j, a] if fresh else buffer[b, i, j, a]


@numba.njit(cache=True, inline="always")
def _lag(x_aug, applied, lag_alpha, applied_next, flat, accel_effect_t):  # pragma: no cover - compiled
    """Step 3 (actuator lag): the AGV moves with the applied acceleration instead of the commanded
    u[n]; the difference enters through A~'s acceleration columns."""
    num, k = x_aug.shape[0], x_aug.shape[1]
    gap = np.empty((num * k, 2))
    for b in range(num):
        for i in range(k):
            r = b * k + i
            for a in range(2):
                commanded = x_aug[b, i, _ACCEL0 + a] + flat[r, 6 + a]
                applied_next[b, i, a] = dynamics.lagged_acceleration(applied[b, i, a], commanded, lag_alpha)
                gap[r, a] = applied_next[b, i, a] - commanded
    correction = np.empty((num * k, accel_effect_t.shape[1]))
    product_into(gap, accel_effect_t, correction)
    for r in range(num * k):
        for j in range(4):
            flat[r, j] += correction[r, j]


@numba.njit(cache=True, inline="always")
def _process_noise(packed, process_position, process_velocity):  # pragma: no cover - compiled
    """Step 3 (process noise): added to the next positions and velocities where drawn."""
    k = packed.shape[1]
    for b in range(process_position.shape[0]):
        for i in range(k):
            for a in range(2):
                packed[b, i, _POS0 + a] += process_position[b, i, a]
    for b in range(process_velocity.shape[0]):
        for i in range(k):
            for a in range(2):
                packed[b, i, _VEL0 + a] += process_velocity[b, i, a]


@numba.njit(cache=True, inline="always")
def _errors(packed, reference, slot, err, squares):  # pragma: no cover - compiled
    """Step 4: the packed error against the reference at slot n+1, and its squares."""
    num, k = packed.shape[0], packed.shape[1]
    for b in range(num):
        s = slot[b] + 1
        for i in range(k):
            r = b * k + i
            for j in range(8):
                e = packed[b, i, j] - reference[b, i, s, j] if j < 6 else packed[b, i, j]
                err[b, i, j] = e
                squares[r, j] = e * e


@numba.njit(cache=True, inline="always")
def _accumulate(inp, out, err):  # pragma: no cover - compiled
    """Step 5: the slot's stage costs summed over AGVs (left to right) and the episode's running
    sums (:data:`TOTALS`, ``out.totals_next`` holding the last slot's) advanced, the outage and
    power sums on command slots only."""
    terms, outage, delivered, costs, totals = out.terms, out.outage, out.delivered, out.costs, out.totals_next
    send, power, drone_next, drone_prev = inp.send, inp.power, inp.drone_next, inp.drone_prev
    num, k = terms.shape[0], terms.shape[1]
    for b in range(num):
        sent = 1.0 if send[b % send.shape[0]] else 0.0
        t, e, o = terms[b, 0, 0], terms[b, 0, 1], outage[b, 0]
        for i in range(1, k):
            t += terms[b, i, 0]
            e += terms[b, i, 1]
            o += outage[b, i]
        costs[b, 0], costs[b, 1], costs[b, 2] = t, e, t + e
        totals[b, 0] += t
        totals[b, 1] += e
        totals[b, 2] += sent * o
        sx, sy = drone_next[b, 0] - drone_prev[b, 0], drone_next[b, 1] - drone_prev[b, 1]
        totals[b, 3] += np.sqrt(sx * sx + sy * sy)
        for i in range(k):
            sq = err[b, i, 0] ** 2 + err[b, i, 1] ** 2
            totals[b, 4 + i] += sq
            totals[b, 4 + k + i] += 0.0 if delivered[b, i] else sent
            totals[b, 4 + 2 * k + i] += sent * power[b, i]
            totals[b, 4 + 3 * k] = max(totals[b, 4 + 3 * k], sq)


@numba.njit([_SLOT_SIGNATURE], cache=True)
def _slot(inputs, packed, constants, outputs):  # pragma: no cover - compiled
    """One slot of B scenarios (see :func:`step`): 1. the links (:func:`_links`) and, under the
    buffered actuator, the buffers (:func:`_buffers`); 2. the transition,
    [x~[n+1], du] = [x~, du applied] @ step_t (:func:`lawn_env.products.product_into`: one summation
    order on every machine and batch size, not BLAS); 3. the disturbance mode's actuator lag (``lag_alpha`` >=
    0) and process noise (where the arrays are not empty); 4. the packed error and the stage terms (e' Q1 e, du'
    Q2 du) = err^2 @ cost_w; 5. the costs and the
    running sums. Reads ``inputs`` (the :class:`SlotInputs` fields), the :class:`Packed` matrices
    and the :data:`SLOT_CONSTANTS` record; writes ``outputs`` (the :class:`SlotOutputs` fields)."""
    inp, mat, out, c = SlotInputs(*inputs), Packed(*packed), SlotOutputs(*outputs), constants[0]
    num, k = inp.x_aug.shape[0], inp.x_aug.shape[1]
    n = num * k
    rows = np.empty((n, 8))
    _links(inp, c, out, rows)
    if inp.buffer.shape[2] > 0:
        _buffers(inp, out)
    packed_rows, err = out.rows[0], out.rows[1]
    flat = packed_rows.reshape((n, 8))
    product_into(rows, mat.step_t, flat)
    if c.lag_alpha >= 0.0:
        _lag(inp.x_aug, inp.applied, c.lag_alpha, out.applied_next, flat, mat.accel_effect_t)
    _process_noise(packed_rows, inp.process_position, inp.process_velocity)
    squares = np.empty((n, 8))
    _errors(packed_rows, inp.reference, inp.slot, err, squares)
    product_into(squares, mat.cost_w, out.terms.reshape((n, 2)))
    out.totals_next[:] = inp.totals
    _accumulate(inp, out, err)


#: The columns of ``SimState.totals`` (B, 5 + 3K): the episode's running sums of the tracking
#: and effort costs, the predicted outage probabilities, the drone's path length, then per AGV the
#: squared position errors, the lost commands and the powers, and last the largest squared position
#: error of any AGV so far (a running maximum). The outage and power sums count the slots that send a command
#: only: on the others nothing is transmitted (MODEL.md §7).
TOTALS = ("tracking", "effort", "outage_p", "path", "sq_error", "outages", "power", "max_sq_error")
#: An episode has diverged when some AGV's position error passed this many metres (the RL interface's
#: termination distance; MODEL.md §6): ``episode_metrics``'s ``diverged``.
DIVERGENCE_DISTANCE_M = 25.0


# ---------------------------------------------------------------------- parameters, state, draws
def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class SimParams:
    """What the config fixes for every episode: sizes, the links (true and planning), the packed
    transition and cost matrices, the area, the fixed path set's reference table (None for random
    paths), the disturbance mode. Build with :meth:`from_config`."""

    config: ScenarioConfig
    num_agvs: int
    num_slots: int
    horizon: int
    steps: int  # reference slots per episode: num_slots + horizon + 1
    slot_s: float
    model: PredictionModel
    link: channel.LinkParams
    planning_link: channel.LinkParams
    packed: Packed  # the transition and the stage cost on packed rows, A~'s acceleration columns
    area: tuple[float, float, float, float]
    area_lo: np.ndarray
    area_hi: np.ndarray
    max_speed: float
    power_budget_w: float
    drone_start: np.ndarray  # (2,)
    envelope: references.Envelope | None  # None: the paths are not fitted into the AGVs' envelope
    fixed_paths: list | None
    fixed_reference: np.ndarray | None  # (K, T, 6) of the fixed path set
    disturbance: DisturbanceConfig
    disturbed: bool
    lag_alpha: float  # exp(-slot / lag) under actuator lag, else -1.0 (no lag)
    constants: np.ndarray  # (1,) of SLOT_CONSTANTS
    every_slot: np.ndarray  # (1,) True: the ``send`` of a config whose every slot sends its commands
    buffer_length: int  # L = N_p - 1 later increments a packet carries under the buffered actuator; 0 under hold

    @classmethod
    def from_config(cls, config: ScenarioConfig) -> SimParams:
        if not isinstance(config, ScenarioConfig):
            raise TypeError(f"config must be a ScenarioConfig, got {type(config).__name__}")
        k, horizon, slots = config.num_agvs, config.control.horizon, config.num_slots
        steps = slots + horizon + 1
        model = PredictionModel.from_config(config)
        q1 = np.asarray(config.control.q1_diag, dtype=float)
        q2 = np.asarray(config.control.q2_diag, dtype=float)
        packed_t, packed_w = packed_step_matrices(model.a_aug, model.b_aug, q1, q2)
        x0, x1, y0, y1 = config.area_m
        area = (float(x0), float(x1), float(y0), float(y1))
        envelope = references.Envelope.from_config(config, steps)
        fixed_paths = references.paper_paths(k, area, envelope) if config.uses_paper_paths else None
        fixed = references.reference_table(fixed_paths, steps, config.slot_s) if fixed_paths is not None else None
        d = config.disturbance
        link = channel.LinkParams.from_config(config)
        lag_alpha = dynamics.lag_alpha(config.slot_s, d.actuator_lag_s)
        return cls(
            config=config, num_agvs=k, num_slots=slots, horizon=horizon, steps=steps, slot_s=config.slot_s,
            model=model, link=link,
            planning_link=channel.LinkParams.from_config(config, planning=True),
            packed=Packed(np.ascontiguousarray(packed_t), np.ascontiguousarray(packed_w),
                          np.ascontiguousarray(model.a_aug[0:4, dynamics.ACCELERATION].T)),
            area=area, area_lo=np.array([area[0], area[2]]), area_hi=np.array([area[1], area[3]]),
            max_speed=config.drone.max_speed_mps,
            power_budget_w=config.power_budget_w, drone_start=np.array(config.drone.start_m, dtype=float),
            envelope=envelope, fixed_paths=fixed_paths, fixed_reference=fixed,
            disturbance=d, disturbed=d.active,
            lag_alpha=lag_alpha,
            constants=_readonly(np.array([(lag_alpha, config.control.accel_max_mps2, link.altitude_sq,
                                           *link.coefficients, link.m)], dtype=SLOT_CONSTANTS)),
            every_slot=np.ones(1, dtype=bool),
            buffer_length=config.control.buffer_length,
        )

    @cached_property
    def packed_args(self) -> tuple:
        """:attr:`packed` as the plain tuple the slot kernel takes."""
        return tuple(self.packed)

    @property
    def command_period(self) -> int:
        """Commands go out at the slots n with n % P == 0 (MODEL.md §7): P of the disturbance mode, else 1."""
        return self.disturbance.control_period_slots if self.disturbed else 1

    @property
    def measurement_noise(self) -> bool:
        d = self.disturbance
        return self.disturbed and (d.measurement_noise_position_m > 0 or d.measurement_noise_velocity_mps > 0)


class SlotDraws(NamedTuple):
    """A slot's randomness for B scenarios: the fading ``m|h|^2`` of every link (B, K) and, in the
    disturbance mode, the wind gust (B, 2) and the process and measurement noise (B, K, 2) each;
    None where the config has none."""

    fading: np.ndarray
    gust: np.ndarray | None = None
    process_position: np.ndarray | None = None
    process_velocity: np.ndarray | None = None
    measurement_position: np.ndarray | None = None
    measurement_velocity: np.ndarray | None = None


def draw_slot(rng: np.random.Generator, params: SimParams, num: int = 1) -> SlotDraws:
    """One slot's randomness for ``num`` scenarios from ``rng``, in this order: the wind gust
    N(0, gust std) (num, 2), the fading Gamma(m, 1) (num, K), the process noise on positions, then
    on velocities (num, K, 2) each, the measurement noise on positions, then on velocities; a term
    the config does not have is not drawn. With ``num = 1`` these are the draws, in the order, that
    one scenario's environment has always made from its generator."""
    k, d = params.num_agvs, params.disturbance
    gust = rng.normal(0.0, d.wind_gust_std_mps, (num, 2)) if params.disturbed and d.wind_gust_std_mps > 0 else None
    fading = channel.sample_normalized_fading(rng, params.link.m, (num, k))
    if not params.disturbed:
        return SlotDraws(fading)
    pos = rng.normal(0.0, d.process_noise_position_m, (num, k, 2)) if d.process_noise_position_m > 0 else None
    vel = rng.normal(0.0, d.process_noise_velocity_mps, (num, k, 2)) if d.process_noise_velocity_mps > 0 else None
    meas: tuple[np.ndarray | None, np.ndarray | None] = (None, None)
    if params.measurement_noise:
        meas = (rng.normal(0.0, d.measurement_noise_position_m, (num, k, 2)),
                rng.normal(0.0, d.measurement_noise_velocity_mps, (num, k, 2)))
    return SlotDraws(fading, gust, pos, vel, *meas)


class Decisions(NamedTuple):
    """A slot's decisions for B scenarios: increments to send (B, K, 2) m/s^2 (saturated by the
    step), feasible powers (B, K) W, the drone's next positions (B, 2) m; or one scenario's, the same
    without the B axis. An action decoded for ``lawn/Comm-v1``'s role has ``increment`` None (the
    MPC decides it: :class:`lawn_env.envs.base.CommRole`). Under the buffered actuator ``plan``
    (B, K, N_p - 1, 2) is the rest of each AGV's planned sequence, which its packet carries after
    the increment (None: zeros, a plan that holds)."""

    increment: np.ndarray | None
    power_w: np.ndarray
    drone_next: np.ndarray
    plan: np.ndarray | None = None


@dataclass(eq=False, slots=True)
class SimState:
    """The episode state of B scenarios, every array with a leading batch axis. ``x_obs`` and
    ``error_obs`` are what the policies observe (the true ``x_aug`` and ``tracking_error``
    without measurement noise); ``reference`` (B, K, T, 6) is a broadcast view of the fixed path
    set's table when there is one; ``totals`` holds the
    episode's running sums (:func:`episode_metrics`)."""

    x_aug: np.ndarray  # (B, K, 6) [x, y, v_x, v_y, u_x[n-1], u_y[n-1]]
    tracking_error: np.ndarray  # (B, K, 6) x~ - x~_ref at slot n
    x_obs: np.ndarray
    error_obs: np.ndarray
    applied: np.ndarray  # (B, K, 2) the applied accelerations (actuator lag)
    drone_position: np.ndarray  # (B, 2) q[n-1], where the drone moves from
    slot: np.ndarray  # (B,) int64
    last_power_w: np.ndarray  # (B, K)
    last_delivered: np.ndarray  # (B, K) bool
    last_outage_probability: np.ndarray  # (B, K)
    reference: np.ndarray  # (B, K, T, 6)
    paths: list  # per scenario, its K paths
    totals: np.ndarray  # (B, 5 + 3K), columns TOTALS
    buffer: np.ndarray  # (B, K, L, 2) the AGVs' buffered increments (L = 0 under the hold actuator)
    buffer_age: np.ndarray  # (B, K) int64: how many of them have been played since their packet (L: spent)

    @property
    def num_envs(self) -> int:
        return self.x_aug.shape[0]


def empty_state(params: SimParams, num: int) -> SimState:
    """B scenarios before their first reset (zeros; :func:`reset` starts them)."""
    k, steps = params.num_agvs, params.steps
    fixed = params.fixed_reference
    reference = np.broadcast_to(fixed, (num, *fixed.shape)) if fixed is not None else np.zeros((num, k, steps, 6))
    x = np.zeros((num, k, 6))
    return SimState(
        x_aug=x, tracking_error=np.zeros((num, k, 6)), x_obs=x, error_obs=np.zeros((num, k, 6)),
        applied=np.zeros((num, k, 2)), drone_position=np.zeros((num, 2)), slot=np.zeros(num, dtype=np.int64),
        last_power_w=np.zeros((num, k)), last_delivered=np.ones((num, k), dtype=bool),
        last_outage_probability=np.zeros((num, k)), reference=reference,
        paths=[params.fixed_paths] * num,
        totals=np.zeros((num, 5 + 3 * k)),
        buffer=np.zeros((num, k, params.buffer_length, 2)),
        buffer_age=np.full((num, k), params.buffer_length, dtype=np.int64),
    )


def reset(params: SimParams, state: SimState, rngs: Sequence[np.random.Generator],
          which: np.ndarray | None = None) -> None:
    """New episodes for the scenarios ``which`` (a mask; all when None), scenario i drawing from
    ``rngs[i]``: its random paths (for a random path set), its initial offsets N(0, offset std)
    (K, 2), then, under measurement noise, the noise of its first observation. Writes those rows of
    ``state`` in place (the reference tables are large); the other rows are untouched."""
    num, k, steps = state.num_envs, params.num_agvs, params.steps
    idx = np.arange(num) if which is None else np.flatnonzero(which)
    cfg = params.config
    for name in ("tracking_error", "applied", "drone_position", "slot", "last_power_w", "last_delivered",
                 "last_outage_probability", "buffer", "buffer_age"):  # new arrays: records and infos keep the old ones
        setattr(state, name, getattr(state, name).copy())
    if params.fixed_reference is None:  # every restarting scenario's paths drawn together, one table call
        paths = references.sample_paths([rngs[i] for i in idx.tolist()], k, cfg.reference.families, params.area,
                                        duration_s=(steps - 1) * params.slot_s, envelope=params.envelope)
        tables = references.reference_table([p for row in paths for p in row], steps, params.slot_s)
        state.reference[idx] = tables.reshape(idx.size, k, steps, 6)
        for j, i in enumerate(idx.tolist()):
            state.paths[i] = paths[j]
    offsets = np.empty((idx.size, k, 2))
    for j, i in enumerate(idx.tolist()):  # after its paths, from the scenario's own generator
        offsets[j] = rngs[i].normal(0.0, cfg.reference.initial_offset_std_m, size=(k, 2))
    start = state.reference[idx, :, 0]
    x_aug = state.x_aug.copy()
    x_aug[idx] = initial_state(start, offsets, params.area_lo, params.area_hi)
    state.x_aug = x_aug
    state.tracking_error[idx] = x_aug[idx] - start
    state.applied[idx] = x_aug[idx, :, dynamics.ACCELERATION]
    if params.measurement_noise:
        state.x_obs, state.error_obs = state.x_obs.copy(), state.error_obs.copy()
        d = params.disturbance
        for i in idx.tolist():  # after the offsets, from the scenario's generator
            pos = rngs[i].normal(0.0, d.measurement_noise_position_m, (k, 2))
            vel = rngs[i].normal(0.0, d.measurement_noise_velocity_mps, (k, 2))
            state.x_obs[i], state.error_obs[i] = measure(x_aug[i], state.tracking_error[i], pos, vel)
    else:
        state.x_obs, state.error_obs = state.x_aug, state.tracking_error
    state.drone_position[idx] = params.drone_start
    state.slot[idx] = 0
    state.last_power_w[idx] = params.power_budget_w / k
    state.last_delivered[idx] = True
    state.buffer[idx] = 0.0  # an episode starts with every buffer spent: a first lost command holds
    state.buffer_age[idx] = params.buffer_length
    state.last_outage_probability[idx] = link_outage(x_aug[idx], state.drone_position[idx], state.last_power_w[idx],
                                                     params.link)[1]
    state.totals = state.totals.copy()
    state.totals[idx] = 0.0


class SlotRecord(NamedTuple):
    """What one slot produced for B scenarios."""

    terms: np.ndarray  # (B, K, 2) per AGV: e' Q1 e at slot n+1 (e: augmented tracking error), du' Q2 du applied
    delivered: np.ndarray  # (B, K) bool
    outage_probability: np.ndarray  # (B, K) closed form at (p, q[n]) for the true link
    applied_increment: np.ndarray  # (B, K, 2) after saturation and delivery, m/s^2
    power_w: np.ndarray  # (B, K)
    drone_position: np.ndarray  # q[n], (B, 2), after the wind
    costs: np.ndarray  # (B, 3) the slot's tracking, effort and stage cost, summed over AGVs left to right

    @property
    def tracking_cost(self) -> np.ndarray:
        """Per AGV e' Q1 e (B, K)."""
        return self.terms[..., 0]

    @property
    def effort_cost(self) -> np.ndarray:
        """Per AGV du' Q2 du (B, K)."""
        return self.terms[..., 1]

    @property
    def stage_cost(self) -> np.ndarray:
        """The slot's stage cost, tracking + effort, as a column (B, 1)."""
        return self.costs[:, 2:3]


_NO_NOISE = np.zeros((0, 0, 2))  # the slot kernel's "no process noise"
_NO_PLAN = np.zeros((0, 0, 0, 2))  # the slot kernel's plan under the hold actuator


def step(params: SimParams, state: SimState, decisions: Decisions, draws: SlotDraws) -> tuple[SimState, SlotRecord]:
    """Advance every scenario one slot: a new state and the slot's record; ``state`` and the
    arguments are not modified. Commands are saturated to the acceleration bound and sent from the
    drone's next position q[n] to the AGVs at their slot-n positions; they arrive with the drawn
    fading. The disturbance mode (MODEL.md §7) runs through the same equations: wind moves the
    drone after its planned move, commands go out only every ``control_period_slots``, the applied
    acceleration lags the commanded one, process noise perturbs the AGVs and measurement noise
    what the policies observe. The decisions may come in any real dtype (the kernel's is float64)."""
    d = params.disturbance
    drone_next = np.asarray(decisions.drone_next, dtype=np.float64)
    if params.disturbed:
        wind = np.asarray(d.wind_mps, dtype=float)
        if draws.gust is not None:
            wind = wind + draws.gust
        drone_next = drone.drift(drone_next, wind, params.slot_s, params.area_lo, params.area_hi)
    x_aug = state.x_aug
    num, k = x_aug.shape[0], x_aug.shape[1]
    increment = np.asarray(decisions.increment, dtype=np.float64)
    power = np.asarray(decisions.power_w, dtype=np.float64)
    send = state.slot % params.command_period == 0 if params.disturbed else params.every_slot
    rows, terms = np.empty((2, num, k, 8)), np.empty((num, k, 2))
    delivered, outage_p = np.empty((num, k), np.bool_), np.empty((num, k))
    applied = state.applied if params.lag_alpha < 0.0 else np.empty((num, k, 2))
    costs, totals = np.empty((num, 3)), np.empty(state.totals.shape)
    plan, buffer_next, age_next = _NO_PLAN, state.buffer, state.buffer_age  # the hold actuator's: unread
    if params.buffer_length:
        plan = _plan(params, decisions.plan, num, k)
        buffer_next, age_next = np.empty(state.buffer.shape), np.empty(state.buffer_age.shape, np.int64)
    inputs = (x_aug, increment, send, power, drone_next, draws.fading, state.reference, state.slot, state.applied,
              _NO_NOISE if draws.process_position is None else draws.process_position,
              _NO_NOISE if draws.process_velocity is None else draws.process_velocity, state.drone_position,
              state.totals, plan, state.buffer, state.buffer_age)  # SlotInputs' fields
    _slot(inputs, params.packed_args, params.constants,
          (rows, terms, delivered, outage_p, applied, costs, totals, buffer_next, age_next))
    packed, err = rows[0], rows[1]
    x_next, error, applied_increment, slot = packed[:, :, 0:6], err[:, :, 0:6], packed[:, :, 6:8], state.slot + 1
    x_obs, error_obs = x_next, error
    if draws.measurement_position is not None and draws.measurement_velocity is not None:  # drawn together
        x_obs, error_obs = measure(x_next, error, draws.measurement_position, draws.measurement_velocity)
    new = SimState(x_next, error, x_obs, error_obs, applied, drone_next, slot, power, delivered, outage_p,
                   state.reference, state.paths, totals, buffer_next, age_next)  # SimState's field order
    record = SlotRecord(terms, delivered, outage_p, applied_increment, power, drone_next, costs)
    return new, record


def _plan(params: SimParams, plan: np.ndarray | None, num: int, k: int) -> np.ndarray:
    """The slot kernel's ``plan`` (B, K, L, 2) float64 of a decision's under the buffered actuator
    (zeros when it has none), each increment clipped to the increment bound Delta-a_max: the packet
    carries the plan inside the control set, whatever a planner left unbounded."""
    length = params.buffer_length
    if plan is None:
        return np.zeros((num, k, length, 2))
    given = np.asarray(plan, dtype=np.float64)
    if given.shape != (num, k, length, 2):
        raise ValueError(f"decisions.plan has shape {given.shape}; the buffered actuator takes the later increments "
                         f"of each AGV's sequence, ({num}, {k}, {length}, 2) (N_p - 1 = {length})")
    bound = params.config.control.accel_increment_max_mps2
    return np.clip(given, -bound, bound)


#: The state's arrays with a leading batch axis that a step replaces (the reference and the paths it
#: never changes); ``x_obs`` and ``error_obs`` may be the same arrays as ``x_aug`` and ``tracking_error``.
_STEPPED = ("x_aug", "tracking_error", "x_obs", "error_obs", "applied", "drone_position", "slot", "last_power_w",
            "last_delivered", "last_outage_probability", "totals", "buffer", "buffer_age")


def step_rows(params: SimParams, state: SimState, decisions: Decisions, draws: SlotDraws,
              rows: np.ndarray) -> tuple[SimState, SlotRecord]:
    """:func:`step` of the scenarios ``rows`` (a (B,) mask) alone, with their rows of the decisions
    and of the draws (drawn for every scenario, so each scenario's numbers do not depend on which
    others step); the other scenarios keep their state, and their record rows are zeros. A vector
    env's scenarios restarted this slot do not step."""
    idx = np.flatnonzero(rows)
    sub = SimState(**{name: getattr(state, name)[idx] for name in (*_STEPPED, "reference")},
                   paths=[state.paths[i] for i in idx.tolist()])
    if state.x_obs is state.x_aug:  # without measurement noise, the observed state is the true one
        sub.x_obs = sub.x_aug
    if state.error_obs is state.tracking_error:
        sub.error_obs = sub.tracking_error
    taken = Decisions(*[None if a is None else np.asarray(a)[idx] for a in decisions])  # type: ignore[arg-type]
    sub_draws = SlotDraws(*[None if d is None else d[idx] for d in draws])  # type: ignore[arg-type]
    new_sub, record = step(params, sub, taken, sub_draws)
    merged: dict[str, Any] = {}
    for name in _STEPPED:
        new = getattr(new_sub, name)
        if name == "x_obs" and new is new_sub.x_aug:
            merged[name] = merged["x_aug"]
        elif name == "error_obs" and new is new_sub.tracking_error:
            merged[name] = merged["tracking_error"]
        else:
            merged[name] = getattr(state, name).copy()
            merged[name][idx] = new
    full = SlotRecord(*(np.zeros((state.num_envs, *a.shape[1:]), a.dtype) for a in record))
    for whole, part in zip(full, record, strict=True):
        whole[idx] = part
    return SimState(**merged, reference=state.reference, paths=state.paths), full


def buffer_queue(buffer: np.ndarray, age: np.ndarray) -> np.ndarray:
    """The increments the AGVs of a buffered actuator play on their next slots without a packet, in
    order: of buffers (..., K, L, 2) and their ages (..., K), (..., K, L, 2) with entry j the buffer's
    element ``age + j``, zero past its end (a new array)."""
    buffer = np.asarray(buffer, dtype=float)
    length = buffer.shape[-2]
    index = np.asarray(age, dtype=np.int64)[..., None] + np.arange(length)
    out = np.take_along_axis(buffer, np.minimum(index, max(length - 1, 0))[..., None], axis=-2) if length else buffer
    return np.where((index < length)[..., None], out, 0.0)


def later_increments(sequence: np.ndarray, length: int) -> np.ndarray:
    """What a buffered actuator's packet carries after the command of the planned increments
    ``sequence`` (..., N, 2), the first being the command: its next ``length`` (L = N_p - 1), zeros past
    the sequence's end (an AGV that has played them all holds), a new array (..., L, 2)."""
    sequence = np.asarray(sequence, dtype=float)
    plan = np.zeros((*sequence.shape[:-2], length, 2))
    later = sequence[..., 1 : 1 + length, :]
    plan[..., : later.shape[-2], :] = later
    return plan


def control_costs(state: SimState, rows: Any = slice(None)) -> np.ndarray:
    """The control cost so far of the scenarios ``rows`` (default: all, (B,)): the running sums of
    their tracking and effort costs."""
    return state.totals[rows, 0] + state.totals[rows, 1]


def episode_metrics(params: SimParams, state: SimState, rows: Sequence[int] | np.ndarray) -> list[dict]:
    """Metrics of MODEL.md §6 over the slots each scenario of ``rows`` has run in its episode (the
    decision time is the caller's), one dict per row: ``slots``, ``control_cost`` (tracking +
    effort), ``tracking_cost``, ``effort_cost``, ``rmse_m``, ``rmse_per_agv_m``, ``outage_rate``,
    ``outage_rate_predicted``, ``outage_rate_per_agv`` (over the commands sent: with commands every
    P slots, the slots n with n % P == 0), ``mean_power_w`` (the power radiated per link, averaged
    over every slot: 0 W on a slot without a command), ``drone_path_length_m``,
    ``max_tracking_error_m`` (the largest position error of any AGV at any slot) and ``diverged`` (1
    when it passed :data:`DIVERGENCE_DISTANCE_M`, else 0)."""
    rows = np.asarray(rows, dtype=np.int64).reshape(-1)
    n, k = state.slot[rows], params.num_agvs
    if np.any(n == 0):
        raise RuntimeError("no slot has been simulated yet")
    t = state.totals[rows]
    period = params.command_period
    sent = (n + period - 1) // period  # the command slots 0, P, 2P, ... among slots 0..n-1 (step's rule)
    nk, per = sent * k, sent[:, None]
    sq_error, outages, power = t[:, 4 : 4 + k], t[:, 4 + k : 4 + 2 * k], t[:, 4 + 2 * k : 4 + 3 * k]
    largest = np.sqrt(t[:, 4 + 3 * k])
    columns = zip(n.tolist(), control_costs(state, rows).tolist(), t[:, 0].tolist(), t[:, 1].tolist(),
                  np.sqrt(sq_error.sum(axis=1) / (n * k)).tolist(), np.sqrt(sq_error / n[:, None]).tolist(),
                  (outages.sum(axis=1) / nk).tolist(), (t[:, 2] / nk).tolist(), (outages / per).tolist(),
                  (power / n[:, None]).tolist(), t[:, 3].tolist(), largest.tolist(),
                  (largest > DIVERGENCE_DISTANCE_M).astype(int).tolist(), strict=True)
    return [dict(zip(_METRICS, values, strict=True)) for values in columns]


_METRICS = ("slots", "control_cost", "tracking_cost", "effort_cost", "rmse_m", "rmse_per_agv_m", "outage_rate",
            "outage_rate_predicted", "outage_rate_per_agv", "mean_power_w", "drone_path_length_m",
            "max_tracking_error_m", "diverged")


# ---------------------------------------------------------------------- the environments' object
@dataclass(frozen=True)
class Snapshot:
    """The full system state an external planner needs at the start of a slot.

    ``x_aug`` (K, 6): augmented AGV states [x, y, v_x, v_y, u_x[n-1], u_y[n-1]] (as measured);
    ``reference`` (K, N_p+1, 6): reference augmented states [x, y, v_x, v_y, a_x, a_y] at slots
    n..n+N_p; ``drone_position`` (2,): q[n-1], the position the drone moves from; ``slot``: n;
    ``config``: the scenario. Arrays are copies.
    """

    x_aug: np.ndarray
    reference: np.ndarray
    drone_position: np.ndarray
    slot: int
    config: ScenarioConfig
    last_power_w: np.ndarray | None = None  # the powers of slot n-1 (warm starts); None when unknown
    #: Under the buffered actuator, (K, N_p - 1, 2): the increments each AGV plays on its next slots
    #: without a packet, in order, zeros once its buffer is spent (:func:`buffer_queue`); None under hold.
    buffer: np.ndarray | None = None


class Simulation:
    """B scenarios of one config (``num_envs``, 1 for the single environments): the frozen
    :class:`SimParams` and the current :class:`SimState`, advanced by :func:`step` and restarted
    by :func:`reset`. The state's arrays read as attributes (``sim.x_aug`` (B, K, 6), ...)."""

    # the state's arrays, properties set after the class from STATE_ARRAYS (every scenario's)
    x_aug: np.ndarray
    tracking_error: np.ndarray
    x_obs: np.ndarray
    error_obs: np.ndarray
    applied: np.ndarray
    drone_position: np.ndarray
    last_power_w: np.ndarray
    last_delivered: np.ndarray
    last_outage_probability: np.ndarray
    reference: np.ndarray
    buffer: np.ndarray
    buffer_age: np.ndarray
    slot: np.ndarray
    paths: list

    def __init__(self, config: ScenarioConfig, num_envs: int = 1):
        if not isinstance(num_envs, (int, np.integer)) or isinstance(num_envs, bool) or num_envs < 1:
            raise ValueError(f"num_envs={num_envs!r}: must be an integer >= 1")
        self.params = SimParams.from_config(config)
        self.config = config
        self.num_envs = int(num_envs)
        self.num_agvs, self.num_slots, self.horizon = config.num_agvs, config.num_slots, config.control.horizon
        self.state = empty_state(self.params, self.num_envs)
        self.started = False
        self._window = np.arange(self.horizon + 1)

    def reset(self, rngs: Sequence[np.random.Generator], which: np.ndarray | None = None) -> None:
        """New episodes for the scenarios ``which`` (all when None), scenario i from ``rngs[i]``."""
        if not self.started and which is not None and not np.all(which):
            raise RuntimeError("the first reset must start every scenario")
        reset(self.params, self.state, rngs, which)
        self.started = True

    def draw(self, rng: np.random.Generator) -> SlotDraws:
        """This slot's randomness for every scenario (:func:`draw_slot`)."""
        return draw_slot(rng, self.params, self.num_envs)

    def step(self, decisions: Decisions, draws: SlotDraws, rows: np.ndarray | None = None) -> SlotRecord:
        """One slot of every scenario (:func:`step`), or of the scenarios ``rows`` (a mask) alone
        (:func:`step_rows`); the new state replaces the old."""
        if rows is None or rows.all():
            self.state, record = step(self.params, self.state, decisions, draws)
        else:
            self.state, record = step_rows(self.params, self.state, decisions, draws, rows)
        return record

    def reference_windows(self) -> np.ndarray:
        """Reference augmented states at slots n..n+N_p of every scenario: (B, K, N_p+1, 6)."""
        state = self.state
        if state.slot.size == 1:  # one scenario: a view
            n = int(state.slot[0])
            return state.reference[:, :, n : n + self.horizon + 1]
        idx = state.slot[:, None] + self._window[None, :]
        return state.reference[np.arange(state.slot.size)[:, None], :, idx].transpose(0, 2, 1, 3)

    def episode_metrics(self, rows: Sequence[int] | np.ndarray = (0,)) -> list[dict]:
        """:func:`episode_metrics` of the scenarios ``rows`` (indices; a single env's is row 0),
        computed together."""
        return episode_metrics(self.params, self.state, rows)

    def row(self, i: int = 0) -> ScenarioView:
        return ScenarioView(self, i)


class ScenarioView:
    """Scenario ``i`` of a :class:`Simulation` as single-scenario arrays (views of row i): what
    the renderer, the planners' snapshots and the single environments' accessors read."""

    # the state's arrays, properties set after the class from STATE_ARRAYS (row i's)
    x_aug: np.ndarray
    tracking_error: np.ndarray
    x_obs: np.ndarray
    error_obs: np.ndarray
    applied: np.ndarray
    drone_position: np.ndarray
    last_power_w: np.ndarray
    last_delivered: np.ndarray
    last_outage_probability: np.ndarray
    reference: np.ndarray
    buffer: np.ndarray
    buffer_age: np.ndarray

    def __init__(self, sim: Simulation, i: int):
        self._sim, self.i = sim, int(i)
        p = sim.params
        self.config, self.area, self.num_agvs, self.num_slots, self.horizon = (
            p.config, p.area, p.num_agvs, p.num_slots, p.horizon)
        self.link, self.planning_link, self.model = p.link, p.planning_link, p.model

    @property
    def slot(self) -> int:
        return int(self._sim.state.slot[self.i])

    @property
    def paths(self) -> list:
        return self._sim.state.paths[self.i]

    @property
    def control_cost(self) -> float:
        """The episode's control cost so far (:func:`control_costs` of this scenario)."""
        return float(control_costs(self._sim.state, self.i))

    @property
    def done(self) -> bool:
        """True once ``num_slots`` slots have run (the episode truncates)."""
        return self.slot >= self.num_slots

    def reference_window(self) -> np.ndarray:
        """Reference augmented states at slots n..n+N_p: (K, N_p+1, 6) (a view)."""
        n = self.slot
        return self._sim.state.reference[self.i, :, n : n + self.horizon + 1]

    def outage_probability(self, power_w: np.ndarray, drone_position: np.ndarray) -> np.ndarray:
        """Closed-form outage of the true link at the current AGV positions."""
        return link_outage(self.x_aug, np.asarray(drone_position, dtype=float), power_w, self.link)[1]

    def planning_success(self, power_w: np.ndarray, drone_position: np.ndarray) -> np.ndarray:
        """psi of the planners' link model (CSI-aware or not, see ChannelConfig) at the measured
        positions (what the planners, ``lawn/Comm-v1``'s MPC among them, plan from)."""
        return link_success(self.x_obs, np.asarray(drone_position, dtype=float), power_w, self.planning_link)

    def drone_target(self, velocity_mps: np.ndarray) -> np.ndarray:
        """Next drone position for a commanded velocity (speed-limited, kept in the area)."""
        p = self._sim.params
        return drone.move_drone(self.drone_position, velocity_mps, p.max_speed, p.slot_s, p.area)

    def snapshot(self) -> Snapshot:
        return Snapshot(
            x_aug=self.x_obs.copy(),  # measured state: what a planner would have
            reference=self.reference_window().copy(),
            drone_position=self.drone_position.copy(),
            slot=self.slot,
            config=self.config,
            last_power_w=self.last_power_w.copy(),
            buffer=buffer_queue(self.buffer, self.buffer_age) if self._sim.params.buffer_length else None,
        )

    def episode_metrics(self) -> dict:
        """Metrics of MODEL.md §6 over the slots run so far (decision time is the caller's)."""
        return self._sim.episode_metrics([self.i])[0]


#: The state's arrays a :class:`Simulation` reads as attributes (``sim.x_aug`` (B, K, 6), ...) and a
#: :class:`ScenarioView` as its row's arrays (``view.x_aug`` (K, 6), ...): properties, not a
#: ``__getattr__`` (a failed attribute lookup costs a step microseconds).
STATE_ARRAYS = ("x_aug", "tracking_error", "x_obs", "error_obs", "applied", "drone_position", "last_power_w",
                "last_delivered", "last_outage_probability", "reference", "buffer", "buffer_age")


def _state_array(name: str) -> property:
    return property(lambda sim: getattr(sim.state, name), doc=f"``state.{name}`` of every scenario.")


def _row_array(name: str) -> property:
    return property(lambda view: getattr(view._sim.state, name)[view.i], doc=f"``state.{name}`` of this scenario.")


for _name in STATE_ARRAYS:
    setattr(Simulation, _name, _state_array(_name))
    setattr(ScenarioView, _name, _row_array(_name))
for _name in ("slot", "paths"):
    setattr(Simulation, _name, _state_array(_name))


class Trail:
    """The positions of one scenario's current episode, slot by slot: what the renderer draws
    behind the drone and the AGVs, and the paths a figure plots. ``restart`` at reset, ``record``
    after every step."""

    def __init__(self, view: ScenarioView):
        self.view = view
        self._states: list[SimState] = []

    def restart(self) -> None:
        self._states = []
        self.record()

    def record(self) -> None:
        # the state itself, not copies: a step makes a new state (it never writes into the old
        # one's arrays); a reset writes into the current one, after which the trail restarts
        self._states.append(self.view._sim.state)

    def trajectories(self) -> dict:
        """Drone (n+1, 2), AGV (n+1, K, 2) and reference (n+1, K, 2) positions of slots 0..n."""
        i, n = self.view.i, len(self._states)
        return {"drone_position": np.array([s.drone_position[i] for s in self._states]),
                "agv_position": np.array([s.x_aug[i, :, POSITION] for s in self._states]),
                "reference_position": np.swapaxes(self.view.reference[:, :n, POSITION], 0, 1)}
